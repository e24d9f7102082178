"""Renderer variant choice: a missing or broken libLLVM falls back to scalar with a
warning, never a crash; the probe runs in a subprocess."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motion.pipeline.frame_output import read_frame
from _scenes import FOUNTAIN, SKINNED_ARM, orange_pixels
from _support import SCENES, run_motion


def _env(tmp_path: Path, lib: str) -> dict[str, str]:
    # a private cache folder: probe results of other tests must not leak in; no GPU either
    # (on a GPU machine `auto` would pick CUDA, never falling back)
    return {"DRJIT_LIBLLVM_PATH": lib, "MOTION_CACHE_DIR": str(tmp_path / "cache"), "CUDA_VISIBLE_DEVICES": ""}


def test_missing_library_falls_back_to_scalar(tmp_path: Path) -> None:
    proc = run_motion("info", "--json", env=_env(tmp_path, str(tmp_path / "libLLVM-missing.so")))
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert info["variant"] == "scalar_rgb" and info["fallback"] is True


@pytest.mark.render
def test_broken_library_renders_with_scalar_and_warns(tmp_path: Path) -> None:
    broken = tmp_path / "libLLVM-broken.so"
    broken.write_bytes(b"\x7fELF this is not a shared library")
    out = tmp_path / "out"
    proc = run_motion(
        "render", str(SCENES / "cannonball.yaml"), "--preset", "ci-smoke", "--frames", "0", "--resolution", "16x8", "-o", str(out),
        env=_env(tmp_path, str(broken)),
    )
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "scalar_rgb" in warnings[0]
    frame = read_frame(out / "cannonball.0000.exr")
    assert frame.meta["variant"] == "scalar_rgb"


def test_working_llvm_is_found_by_default() -> None:
    from motion.pipeline.variant import choose

    choice = choose("auto")
    # this machine (and CI) has libllvm19 installed by tools/setup.sh
    assert choice.variant in ("llvm_ad_rgb", "cuda_ad_rgb"), choice


def test_scalar_fallback_draws_particles(tmp_path: Path) -> None:
    """Under `scalar_rgb` (Mitsuba's `path`, one instant) particles are spheres too, as the
    vectorised renderer draws them (they were left out, and a particle shot rendered empty)."""
    scene = tmp_path / "fountain.yaml"
    scene.write_text(FOUNTAIN)
    out = tmp_path / "out"
    proc = run_motion("render", str(scene), "--frames", "10", "--variant", "scalar_rgb", "--no-denoise", "-o", str(out), "--deliver", "none",
                      env={"MOTION_CACHE_DIR": str(tmp_path / "cache"), "CUDA_VISIBLE_DEVICES": ""})
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(out / "fountain.0010.exr")
    assert frame.meta["variant"] == "scalar_rgb"
    assert orange_pixels(frame.rgba) > 20  # orange sparks on the grey sky


DEFORMING = """
timeline: {fps: 24, first: 0, last: 24}
camera: {type: orthographic, position: [0, 1, -6], look_at: [0, 1, 0], ortho_width: 4}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: arm, type: diffuse, color: [0.9, 0.2, 0.2]}, {name: dart, type: diffuse, color: [0.2, 0.2, 0.9]}]
objects:
""" + SKINNED_ARM + """\
  - name: darts
    shape: cube
    size: [0.2, 0.15, 0.4]
    material: dart
    deform: {type: flock, count: 12, seed: 3, spawn_center: [-1, 1, 0], spawn_size: [0.6, 0.6, 0.6], speed: 1, goal: [1, 1, 0],
             bounds: {min: [-2, 0, -1], max: [2, 2.5, 1]}}
render: {resolution: [48, 48], spp: 64, max_depth: 2, motion_blur: off}
"""


def test_scalar_fallback_draws_deforming_meshes(tmp_path: Path) -> None:
    """Under `scalar_rgb` a skinned arm (bent 90 degrees at frame 24) and a flock's agents
    are drawn as the vectorised renderer draws them (`instant.add_deforming`): before, the
    arm was its undeformed bind mesh and a flock failed the frame with a TypeError."""
    scene = tmp_path / "deforming.yaml"
    scene.write_text(DEFORMING)
    images = {}
    for variant in ("scalar_rgb", "auto"):
        out = tmp_path / variant
        proc = run_motion("render", str(scene), "--frames", "24", "--variant", variant, "--no-denoise", "-o", str(out), "--deliver", "none",
                          env={"MOTION_CACHE_DIR": str(tmp_path / "cache"), "CUDA_VISIBLE_DEVICES": ""})
        assert proc.returncode == 0, proc.stderr
        images[variant] = read_frame(out / "deforming.0024.exr").rgba[..., :3]
    red = {v: img[..., 0] > img[..., 1] + 0.3 for v, img in images.items()}
    blue = {v: img[..., 2] > img[..., 1] + 0.3 for v, img in images.items()}
    assert red["auto"].sum() > 50 and blue["auto"].sum() > 10
    # the same pixels covered, to a pixel's edge here and there
    assert (red["scalar_rgb"] != red["auto"]).sum() <= 0.05 * red["auto"].sum()
    assert (blue["scalar_rgb"] != blue["auto"]).sum() <= 0.15 * blue["auto"].sum() + 2
