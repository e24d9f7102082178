"""Denoising (issue 13): OIDN on the frame with albedo + normal guides, in the worker.

- a flat-lit diffuse plane: the denoised image converges to the closed-form value;
- the guides are motion-blurred like the beauty: a moving albedo edge gives the trapezoid;
- frames are bit-identical across worker and shard counts with denoising and the temporal
  mode on, and carry the noisy beauty, the guides and the denoised image as layers;
- a broken OIDN binding is one line naming the package, exit 2; temporal without denoise
  is a scene error; `--aov` picks the layers (the albedo pass among them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import column_x, load, render_layers
from _support import run_motion
from motion.pipeline.frame_output import read_frame
from motion.pipeline.render.output.temporal import RADIUS

pytestmark = pytest.mark.render

# A diffuse plane of albedo 0.5 facing an orthographic camera under an environment map of
# radiance 1 (one pole row aside): every pixel's radiance is 0.5 * 1 (direct light only: max_depth 2).
# A map, not a `constant` light: a constant (or smooth) sky is reached by BSDF sampling
# alone, which is exact on a lone diffuse plane (no noise to remove); this map is
# light-sampled with MIS. The box
# filter keeps each pixel's noise its own: OIDN removes uncorrelated pixel noise; the
# gaussian's 5x5 splat correlates it, and OIDN keeps much of it as texture (docs/denoise.md).
PLANE = """
timeline: {fps: 24, first: 0, last: 0}
camera: {type: orthographic, position: [0, 0, -5], look_at: [0, 0, 0], ortho_width: 4}
lights: [{type: envmap, file: white.pfm}]
materials: [{name: m, type: diffuse, color: 0.5}]
objects:
  - {name: plane, shape: rectangle, width: 10, height: 10, material: m, transform: {rotate: {euler: [0, 180, 0]}}}
render: {resolution: [64, 48], spp: SPP, max_depth: 2, denoise: oidn, filter: box}
"""


def _white_map(folder: Path) -> None:
    """PLANE's environment: radiance 1, but one pole's row at 4: not smooth, so the map is
    light-sampled (a smooth one is reached by BSDF sampling alone, exact here); the pole
    lies in the plane's own plane (cos ~ 0 for its whole row: < 4e-4 of extra radiance)."""
    white = np.ones((32, 64, 3), "<f4")
    white[0] = 4.0
    (folder / "white.pfm").write_bytes(b"PF\n64 32\n-1.0\n" + white.tobytes())


def test_denoised_flat_plane_converges_to_the_closed_form(tmp_path: Path) -> None:
    from motion.pipeline.render.output.denoise import denoise_frame

    _white_map(tmp_path)
    errors = {}
    for spp in (1, 8):
        img, aovs = render_layers(load(tmp_path, PLANE.replace("SPP", str(spp)), f"plane{spp}.yaml"), 0)
        assert set(aovs) == {"albedo", "N"}  # the guides come with denoise: oidn
        assert np.allclose(aovs["albedo"], 0.5, atol=1e-5)
        out, layers, meta = denoise_frame(img, aovs)
        noisy, clean = img[..., :3], out[..., :3]
        assert np.array_equal(layers["noisy"], img) and meta["rgba"] == "denoised"
        # no bias beyond 1% on the mean; per pixel far closer than the noisy image
        assert abs(clean.mean() - 0.5) < 0.005, (spp, clean.mean())
        errors[spp] = (np.abs(noisy - 0.5).mean(), np.abs(clean - 0.5).mean(), np.percentile(np.abs(clean - 0.5), 99))
        assert errors[spp][1] < 0.25 * errors[spp][0], errors
        assert errors[spp][2] < 0.06, errors
    assert errors[8][1] < errors[1][1], errors  # more samples: closer still


W, ORTHO, BAR_W = 200, 4.0, 0.5
# a diffuse bar of albedo 0.8 slides 1 m (40 px) during the 1/48 s shutter in front of an
# environment of radiance 0.3 (whose albedo guide is the clamped radiance, 0.3)
BAR = f"""
timeline: {{fps: 24, first: 0, last: 0}}
camera: {{type: orthographic, position: [0, 0, -5], look_at: [0, 0, 0], ortho_width: {ORTHO}, shutter: {{angle: 180}}}}
lights: [{{type: constant, radiance: 0.3}}]
materials: [{{name: m, type: diffuse, color: 0.8}}]
objects:
  - name: bar
    shape: rectangle
    width: {BAR_W}
    height: 4
    material: m
    transform: {{rotate: {{euler: [0, 180, 0]}}}}
    motion: {{type: procedural, generators: [{{type: ballistic, x0: [-0.5, 0, 0], v0: [48, 0, 0], a: [0, 0, 0]}}]}}
render: {{resolution: [{W}, 4], spp: 64, filter: box, max_depth: 2}}
output: {{aovs: [albedo, normal]}}
"""


def _trapezoid(x_open: float, x_close: float) -> np.ndarray:
    """Per pixel: the fraction of (shutter time x pixel width) the bar covers the pixel."""
    pitch = ORTHO / W
    centres = column_x(W, ORTHO)
    c = x_open + (x_close - x_open) * (np.arange(20000) + 0.5) / 20000
    lo = np.maximum(centres[:, None] - pitch / 2, c[None, :] - BAR_W / 2)
    hi = np.minimum(centres[:, None] + pitch / 2, c[None, :] + BAR_W / 2)
    return (np.clip(hi - lo, 0, None) / pitch).mean(axis=1)


def test_guides_are_motion_blurred_like_the_beauty(tmp_path: Path) -> None:
    _, aovs = render_layers(load(tmp_path, BAR, "bar.yaml"), 0)
    cover = _trapezoid(-1.0, 0.0)  # shutter centred on t = 0: the centre moves -1 -> 0
    albedo = aovs["albedo"][..., 0].mean(axis=0)
    normal_z = aovs["N"][..., 2].mean(axis=0)
    expected = 0.3 + (0.8 - 0.3) * cover
    err = np.abs(albedo - expected)
    assert err.mean() < 0.005 and err.max() < 0.04, (err.mean(), err.max())
    # the ramps are real: a frame-time (unblurred) guide would be a 10-px box, off by far more
    sharp = 0.3 + 0.5 * _trapezoid(-0.5, -0.5)
    assert np.abs(albedo - sharp).mean() > 10 * err.mean()
    # the bar faces the camera (N = -z); the environment has no normal (0)
    assert np.abs(normal_z + cover).mean() < 0.01


SEQ = """
timeline: {fps: 24, first: 0, last: 3}
camera: {type: perspective, position: [0, 1, -4], look_at: [0, 0.5, 0], fov: 50}
lights: [{type: constant, radiance: 0.6}, {type: point, position: [2, 3, -2], intensity: 20}]
materials: [{name: floor, type: diffuse, color: 0.4}, {name: red, type: diffuse, color: [0.8, 0.2, 0.1]}]
objects:
  - {name: floor, shape: rectangle, width: 8, height: 8, material: floor, transform: {rotate: {euler: [-90, 0, 0]}}}
  - name: ball
    shape: sphere
    radius: 0.4
    material: red
    transform: {translate: [-1, 0.4, 0]}
    motion: {type: procedural, generators: [{type: ballistic, v0: [12, 0, 0], a: [0, 0, 0]}]}
render: {resolution: [32, 24], spp: 4, max_depth: 3, denoise: oidn, temporal: reproject}
"""


def _frames(folder: Path) -> dict[str, np.ndarray]:
    return {p.name: read_frame(p).rgba for p in sorted(folder.glob("*.exr"))}


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_denoised_frames_are_bit_identical_across_workers_and_shards(tmp_path: Path) -> None:
    scene = tmp_path / "seq.yaml"
    scene.write_text(SEQ.replace("temporal: reproject}", "temporal: reproject, variant: llvm_ad_rgb}"))  # threads are the CPU's, on a GPU machine too
    one, two = tmp_path / "one", tmp_path / "sharded"
    proc = run_motion("render", str(scene), "-o", str(one), "--workers", "1", "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    # shard 1 (frames 0, 1) cannot finish a frame whose neighbours reach frame 2 (not there
    # yet); shard 2 finishes its own frames 2 and 3; the gather run below finishes the rest
    waiting = {f"seq.{f:04d}.exr" for f in (0, 1) if f + RADIUS >= 2}
    for part in ("1/2", "2/2"):  # two shards into one folder, 2 worker processes x 1 thread
        proc = run_motion("render", str(scene), "-o", str(two), "--shard", part, "--workers", "2")
        assert proc.returncode == 0, proc.stderr
        pending = {p.name for p in two.glob("*.exr") if read_frame(p).meta["temporal"] == "pending"}
        assert pending == waiting, (part, pending)
    proc = run_motion("render", str(scene), "-o", str(two), "--threads", "2")
    assert proc.returncode == 0, proc.stderr
    a, b = _frames(one), _frames(two)
    assert sorted(a) == [f"seq.000{i}.exr" for i in range(4)] and sorted(a) == sorted(b)
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    frame = read_frame(one / "seq.0001.exr")
    assert {"noisy", "albedo", "N", "motion"} <= set(frame.aovs)
    meta = frame.meta
    assert meta["denoise"] == "oidn" and meta["rgba"] == "denoised" and meta["temporal"] == "reproject"
    assert meta["denoiser"].startswith("Intel Open Image Denoise") and "mitsuba-oidn" in meta["denoiser"]
    assert meta["denoise_guides"] == "albedo,N"
    # the default RGBA is the denoised image, not the noisy layer
    assert not np.array_equal(frame.rgba[..., :3], frame.aovs["noisy"][..., :3].astype(np.float16).astype(np.float32))
    # every rendered frame's row of the report says what denoising it cost
    import json

    rows = [r for r in json.loads((one / "render-report.json").read_text())["frames"] if r["status"] == "rendered"]
    assert len(rows) == 4 and all(r["denoise_s"] > 0 for r in rows), rows


def test_broken_oidn_is_one_line_naming_the_package(tmp_path: Path) -> None:
    # a broken install: the package imports its missing shared library and fails
    fake = tmp_path / "site" / "mitsuba_oidn"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('libmitsuba_oidn_core.so: cannot open shared object file: No such file or directory')\n")
    scene = tmp_path / "plane.yaml"
    scene.write_text(PLANE.replace("SPP", "2"))
    _white_map(tmp_path)
    proc = run_motion("render", str(scene), "-o", str(tmp_path / "out"), env={"PYTHONPATH": str(fake.parent)})
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "mitsuba-oidn" in lines[0] and "cannot open shared object" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()
    # without denoising the same environment renders; --aov picks the layers, in any order
    proc = run_motion("render", str(scene), "-o", str(tmp_path / "out"), "--no-denoise", "--aov", "albedo", "--aov", "depth", env={"PYTHONPATH": str(fake.parent)})
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(tmp_path / "out" / "plane.0000.exr")
    assert frame.meta.get("denoise") is None and set(frame.aovs) == {"albedo", "Z"}
    assert np.allclose(frame.aovs["albedo"], 0.5, atol=1e-5) and np.allclose(frame.aovs["Z"], 5.0, atol=1e-3)


def test_temporal_without_denoise_is_a_scene_error(tmp_path: Path) -> None:
    scene = tmp_path / "bad.yaml"
    scene.write_text(PLANE.replace("SPP", "2").replace("denoise: oidn", "denoise: off, temporal: reproject"))
    _white_map(tmp_path)
    proc = run_motion("validate", str(scene))
    assert proc.returncode == 2
    assert "render" in proc.stderr and "needs denoise: oidn" in proc.stderr and "Traceback" not in proc.stderr
