"""Stochastic motion blur against closed forms: a sliding bar's trapezoid, a spinning
bar's angular sector, and where the shutter position puts the blur."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import column_x, load, render

pytestmark = pytest.mark.render

W, ORTHO = 200, 4.0
BAR_W, TRAVEL = 0.5, 1.0  # metres; the bar moves TRAVEL during the shutter


def _slide_scene(position: str = "center", mode: str = "stochastic", spp: int = 256, subframes: int = 8) -> str:
    # 24 fps, 180-degree shutter: open 1/48 s; v = TRAVEL * 48 m/s along +x
    return f"""
timeline: {{fps: 24, first: 0, last: 2}}
camera:
  type: orthographic
  position: [0, 0, -5]
  look_at: [0, 0, 0]
  ortho_width: {ORTHO}
  shutter: {{angle: 180, position: {position}}}
materials: [{{name: black, type: diffuse, color: 0.0}}]
objects:
  - name: bar
    shape: rectangle
    width: {BAR_W}
    height: 4
    emission: {{radiance: 1.0}}
    material: black
    transform: {{rotate: {{euler: [0, 180, 0]}}}}
    motion:
      type: procedural
      generators: [{{type: ballistic, x0: [-0.5, 0, 0], v0: [{TRAVEL * 48}, 0, 0], a: [0, 0, 0]}}]
render: {{resolution: [{W}, 4], spp: {spp}, filter: box, max_depth: 2, motion_blur: {mode}, subframes: {subframes}, shutter_samples: 9}}
"""


def _trapezoid(x_open: float, x_close: float) -> np.ndarray:
    """Closed form, per pixel: the fraction of (shutter time x pixel width) during which the
    bar covers the pixel. The bar's centre moves linearly from x_open to x_close, so the
    exposure is box(BAR_W) * box(travel) (a trapezoid), integrated over each pixel."""
    pitch = ORTHO / W
    centres = column_x(W, ORTHO)
    u = (np.arange(20000) + 0.5) / 20000  # midpoint rule over the shutter, exact to ~1e-4
    c = x_open + (x_close - x_open) * u
    lo = np.maximum(centres[:, None] - pitch / 2, c[None, :] - BAR_W / 2)
    hi = np.minimum(centres[:, None] + pitch / 2, c[None, :] + BAR_W / 2)
    return (np.clip(hi - lo, 0, None) / pitch).mean(axis=1)


def _profile(img: np.ndarray) -> np.ndarray:
    return img[..., 0].mean(axis=0)


def test_sliding_bar_matches_trapezoid_and_subframes_do_not(tmp_path: Path) -> None:
    # frame 0, shutter centred on t = 0: the centre moves from -0.5 - 0.5 to -0.5 + 0.5
    expected = _trapezoid(-1.0, 0.0)
    (stochastic,), _, _ = render(load(tmp_path, _slide_scene()), [0])
    err_stochastic = np.abs(_profile(stochastic) - expected)
    (ghosts,), _, _ = render(load(tmp_path, _slide_scene(mode="subframes", subframes=4), "sub.yaml"), [0])
    err_subframes = np.abs(_profile(ghosts) - expected)
    # stochastic: only sampling noise (256 spp x 4 rows per column)
    assert err_stochastic.max() < 0.06, err_stochastic.max()
    assert err_stochastic.mean() < 0.01, err_stochastic.mean()
    # 4 sub-frames: a staircase of 4 ghost copies, off by up to ~1/8 of full exposure
    assert err_subframes.max() > 0.1 and err_subframes.mean() > 2 * err_stochastic.mean()


@pytest.mark.parametrize(("position", "x_open", "x_close"), [("start", -0.5, 0.5), ("center", -1.0, 0.0), ("end", -1.5, -0.5)])
def test_shutter_position_shifts_the_blur(tmp_path: Path, position: str, x_open: float, x_close: float) -> None:
    # frame 0 is at t = 0 where the bar's centre is at x = -0.5
    (img,), _, _ = render(load(tmp_path, _slide_scene(position=position, spp=64)), [0])
    profile = _profile(img)
    x = column_x(W, ORTHO)
    centroid = float((profile * x).sum() / profile.sum())
    assert centroid == pytest.approx((x_open + x_close) / 2, abs=0.02)
    assert np.abs(profile - _trapezoid(x_open, x_close)).mean() < 0.02


def _spin_scene(spp: int = 256) -> str:
    # a 2 m x 0.2 m emissive bar turning 90 degrees during the 1/48 s shutter, about the
    # view axis: 4320 degrees/s; at frame 0 it sweeps -45..+45 degrees
    return f"""
timeline: {{fps: 24, first: 0, last: 0}}
camera: {{type: orthographic, position: [0, 0, -5], look_at: [0, 0, 0], ortho_width: 2.4}}
materials: [{{name: black, type: diffuse, color: 0.0}}]
objects:
  - name: bar
    shape: rectangle
    width: 2.0
    height: 0.2
    emission: {{radiance: 1.0}}
    material: black
    transform: {{rotate: {{euler: [0, 180, 0]}}}}
    motion:
      type: procedural
      generators: [{{type: turntable, axis: [0, 0, 1], rate: 4320}}]
render: {{resolution: [240, 240], spp: {spp}, filter: box, max_depth: 2, shutter_samples: 2}}
"""
# shutter_samples: 2 bakes only the shutter's endpoints, 90 degrees apart, so the pose at
# every sample time comes from interpolating across the whole sweep: only a true slerp
# keeps the bar whole and turning at constant speed.


def test_spinning_bar_gives_the_angular_sector(tmp_path: Path) -> None:
    (img,), _, _ = render(load(tmp_path, _spin_scene()), [0])
    lum = img[..., 0]
    n = lum.shape[0]
    pitch = 2.4 / n
    c = (np.arange(n) + 0.5) * pitch - 1.2
    yy, xx = np.meshgrid(-c, -c, indexing="ij")  # image y down, camera +X left
    r = np.hypot(xx, yy)
    ang = np.degrees(np.arctan2(yy, xx))
    ang = (ang + 90) % 180 - 90  # the bar is symmetric: fold onto [-90, 90)
    ring = (r > 0.85) & (r < 0.95)
    # closed form on radius r: the bar (half-width h) covers angle 2 asin(h / r) of the
    # 90-degree sweep, at every angle inside the sector (slerp: constant angular speed)
    expected = 2 * np.degrees(np.arcsin(np.clip(0.1 / np.maximum(r, 1e-9), 0, 1))) / 90.0
    inside = ring & (np.abs(ang) < 35)
    outside = ring & (np.abs(ang) > 55)
    target = expected[inside].mean()
    assert abs(lum[inside].mean() - target) < 0.03 * target
    # flat across the sector (constant angular speed, constant bar length): any
    # interpolation that is not a slerp (a matrix or component lerp shrinks or speeds up
    # the bar mid-shutter) bends this profile by 5-30%; sampling noise here is ~1%
    bins = [lum[inside & (ang >= a) & (ang < a + 10)].mean() for a in range(-35, 35, 10)]
    assert max(abs(b - target) for b in bins) < 0.05 * target, bins
    assert lum[outside].mean() < 0.01
