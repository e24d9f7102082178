"""Renderer variant choice: a missing or broken libLLVM falls back to scalar with a
warning, never a crash; the probe runs in a subprocess."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motion.pipeline.frame_output import read_frame
from _scenes import FOUNTAIN, orange_pixels
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
