"""Renderer variant choice: a missing or broken libLLVM falls back to scalar with a
warning, never a crash; the probe runs in a subprocess."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motion.pipeline.frame_output import read_frame
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


_FOUNTAIN = """\
timeline: {fps: 24, first: 0, last: 10}
camera: {position: [0, 1.5, -5], look_at: [0, 1.2, 0], fov: 45}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: spark, type: diffuse, color: [1.0, 0.45, 0.05]}]
objects:
  - name: fountain
    shape: particles
    radius: 0.04
    material: spark
    emitter: {rate: 1500, lifetime: 2.0, position: [0, 0.1, 0], direction: [0, 1, 0], speed: 5, spread: 20, seed: 3}
render: {resolution: [64, 48], spp: 4, max_depth: 2, shutter_samples: 5}
"""


def test_scalar_fallback_draws_particles(tmp_path: Path) -> None:
    """Under `scalar_rgb` (Mitsuba's `path`, one instant) particles are spheres too, as the
    vectorised renderer draws them (they were left out, and a particle shot rendered empty)."""
    scene = tmp_path / "fountain.yaml"
    scene.write_text(_FOUNTAIN)
    out = tmp_path / "out"
    proc = run_motion("render", str(scene), "--frames", "10", "--variant", "scalar_rgb", "--no-denoise", "-o", str(out), "--deliver", "none",
                      env={"MOTION_CACHE_DIR": str(tmp_path / "cache"), "CUDA_VISIBLE_DEVICES": ""})
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(out / "fountain.0010.exr")
    assert frame.meta["variant"] == "scalar_rgb"
    r, g, b = frame.rgba[..., 0], frame.rgba[..., 1], frame.rgba[..., 2]
    assert int(((r > g + 0.05) & (g > b + 0.05)).sum()) > 20  # orange sparks on the grey sky
