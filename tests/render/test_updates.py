"""Warm frames follow what animates besides rigid poses: lights that move or change, and
movers whose scale is keyed; without compiling new kernels."""

from __future__ import annotations

from pathlib import Path

import pytest

from _render_support import load, render

pytestmark = pytest.mark.render

SCENE = """
timeline: {fps: 24, first: 0, last: 24}
camera: {type: orthographic, position: [0, 5, 0.001], look_at: [0, 0, 0], ortho_width: 6}
lights:
  - name: lamp
    type: point
    position: [0, 1, 0]
    intensity: 4.0
    motion:
      type: keyframes
      channels: {translate: {keys: [{time: 0, value: [-2, 1, 0]}, {time: 24, value: [2, 1, 0]}]}}
materials: [{name: m, type: diffuse, color: 0.8}]
objects:
  - {name: floor, shape: rectangle, width: 6, height: 6, material: m, transform: {rotate: {euler: [-90, 0, 0]}}}
  - name: blob
    shape: sphere
    radius: 0.3
    material: m
    emission: {radiance: 50.0}
    transform: {translate: [0, 0.5, 2]}
    motion:
      type: keyframes
      channels: {scale: {keys: [{time: 0, value: 1.0}, {time: 24, value: 2.0}]}}
render: {resolution: [60, 60], spp: 4, max_depth: 2, motion_blur: off}
"""


def test_moving_light_and_keyed_scale(tmp_path: Path) -> None:
    images, stats, renderer = render(load(tmp_path, SCENE), [0, 12, 24])
    assert renderer.mover_names == ["blob"]
    lum = [img[..., :3].mean(axis=2) for img in images]
    # the lamp travels from x = -2 to x = +2; camera +X is image left here (looking down -y
    # with up +z... whichever way, the bright side must swap between the first and last frame)
    left = [float(im[:, :20].mean()) for im in lum]
    right = [float(im[:, 40:].mean()) for im in lum]
    assert (left[0] - right[0]) * (left[2] - right[2]) < 0, (left, right)
    assert abs(left[1] - right[1]) < 0.5 * abs(left[0] - right[0])  # centred at mid-shot
    assert stats[2].kernels_compiled == 0 and stats[1].kernels_compiled == 0
    # a moving point light is posed per path by the integrator (opaque frame data), not
    # rebuilt as a scene parameter
    assert [light.name for _, light in renderer.moving_lights] == ["lamp"]
    assert not any(k.startswith("lamp.") for k in stats[1].updated_params)
    assert any(k.startswith("mover:blob") for k in stats[2].updated_params)
    # the emissive blob's scale goes 1 -> 1.5 -> 2: its disk covers ~2.25x and ~4x the
    # pixels of frame 0 (a little more: the pixel filter's soft rim scales too)
    area = [int((im > 10.0).sum()) for im in lum]
    assert 1.9 < area[1] / area[0] < 2.8 and 3.5 < area[2] / area[0] < 5.0, area


ZOOM = """
timeline: {fps: 24, first: 0, last: 24}
camera:
  type: orthographic
  position: [0, 0, -5]
  look_at: [0, 0, 0]
  ortho_width: 2
  motion: {type: keyframes, channels: {ortho_width: {keys: [{time: 0, value: 2.0}, {time: 24, value: 4.0}]}}}
materials: [{name: black, type: diffuse, color: 0.0}]
objects:
  - {name: card, shape: rectangle, width: 1, height: 1, material: black, emission: {radiance: 1.0},
     transform: {rotate: {euler: [0, 180, 0]}}}
render: {resolution: [40, 40], spp: 4, max_depth: 2, filter: box, motion_blur: off}
"""


def test_keyed_orthographic_width_zooms(tmp_path: Path) -> None:
    (near, far), stats, _ = render(load(tmp_path, ZOOM), [0, 24])
    covered = [int((img[..., 0] > 0.5).sum()) for img in (near, far)]
    # a 1 m card: 20 px wide at 2 m across 40 px, 10 px at 4 m: area 400 -> 100
    assert covered == [400, 100], covered
    assert stats[1].kernels_compiled == 0


def test_direct_integrator_is_one_bounce(tmp_path: Path) -> None:
    room = """
camera: {position: [0, 1, 3], look_at: [0, 0.5, 0]}
materials: [{name: white, type: diffuse, color: 0.8}]
objects:
  - {name: floor, shape: rectangle, width: 4, height: 4, material: white, transform: {rotate: {euler: [-90, 0, 0]}}}
  - {name: wall, shape: rectangle, width: 4, height: 4, material: white, transform: {translate: [0, 2, -1]}}
  - {name: sky, shape: rectangle, width: 0.5, height: 0.5, emission: {radiance: 20}, transform: {translate: [0, 1.9, 0], rotate: {euler: [90, 0, 0]}}}
render: {resolution: [32, 24], spp: 16, max_depth: 6, integrator: %s, motion_blur: off}
"""
    (path_img,), _, _ = render(load(tmp_path, room % "path", "path.yaml"), [0])
    (direct_img,), _, r = render(load(tmp_path, room % "direct", "direct.yaml"), [0])
    assert r.max_depth == 2
    assert direct_img[..., :3].mean() < 0.9 * path_img[..., :3].mean()  # no interreflection


def test_keyed_envmap_warm_frames_follow_without_reading_the_map_again(tmp_path: Path) -> None:
    # an environment map whose scale is keyed: each warm frame takes the frame's scale,
    # bit for bit what a cold render of that frame gives, from the pixels loaded on the
    # cold frame (the map's file may be gone by then: it is not read again)
    import numpy as np

    sky = np.array([[1.0, 0.2, 0.1], [0.1, 0.9, 0.2], [0.2, 0.1, 1.0], [0.8, 0.8, 0.8]] * 2, dtype="<f4").reshape(2, 4, 3)
    (tmp_path / "sky.pfm").write_bytes(b"PF\n4 2\n-1.0\n" + sky.tobytes())
    scene = """
timeline: {fps: 24, first: 0, last: 24}
camera: {position: [0, 1, 3], look_at: [0, 0.5, 0], fov: 60}
lights:
  - {type: envmap, file: sky.pfm, scale: 1.0,
     motion: {type: keyframes, channels: {scale: {keys: [{time: 0, value: 1.0}, {time: 24, value: 3.0}]}}}}
materials: [{name: white, type: diffuse, color: 0.8}]
objects:
  - {name: floor, shape: rectangle, width: 4, height: 4, material: white, transform: {rotate: {euler: [-90, 0, 0]}}}
render: {resolution: [32, 24], spp: 4, max_depth: 3, motion_blur: off}
"""
    loaded = load(tmp_path, scene)
    (first,), _, renderer = render(loaded, [0])
    (tmp_path / "sky.pfm").rename(tmp_path / "gone.pfm")
    (warm,), stats, _ = render(loaded, [12], renderer=renderer)
    assert any(k.endswith(".scale") for k in stats[0].updated_params) and stats[0].kernels_compiled == 0
    (tmp_path / "gone.pfm").rename(tmp_path / "sky.pfm")
    (cold,), _, _ = render(loaded, [12])
    np.testing.assert_array_equal(warm, cold)
    assert warm[..., :3].mean() > 1.5 * first[..., :3].mean()  # scale 2 at frame 12 against 1
