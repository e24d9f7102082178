"""CI smoke: every example scene renders at the ci-smoke preset through `motion render`,
as a user types it; the EXRs read back with the right size, channels and real pixels."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.frame_output import read_frame
from _support import SCENES, run_motion
from farm_util import ROOT, frames_in

EXAMPLES = sorted(p.stem for p in SCENES.glob("*.yaml"))


@pytest.mark.render
@pytest.mark.parametrize("name", EXAMPLES)
def test_example_renders_at_ci_smoke(tmp_path: Path, name: str) -> None:
    out = tmp_path / name
    proc = run_motion("render", str(SCENES / f"{name}.yaml"), "--preset", "ci-smoke", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    frames = sorted(out.glob(f"{name}.*.exr"))
    assert len(frames) == 3, [p.name for p in frames]
    for path in frames:
        frame = read_frame(path)
        assert frame.rgba.shape == (36, 64, 4)
        rgb = frame.rgba[..., :3]
        assert np.isfinite(rgb).all()
        assert rgb.std() > 1e-3, f"{path.name} is constant"
        meta = frame.meta
        assert meta["frame"] == int(path.name.split(".")[-2])
        assert meta["spp"] == 4
        assert frame.header["framesPerSecond"] == 24


@pytest.mark.render
def test_cannonball_frame_metadata_and_names(tmp_path: Path) -> None:
    proc = run_motion("render", str(SCENES / "cannonball.yaml"), "--preset", "ci-smoke", "--frames", "12-13", "-o", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    names = sorted(p.name for p in tmp_path.glob("*.exr"))
    assert names == ["cannonball.0012.exr", "cannonball.0013.exr"]
    frame = read_frame(tmp_path / "cannonball.0012.exr")
    meta = frame.meta
    assert meta["time"] == pytest.approx(0.5)
    assert meta["shutter_close"] - meta["shutter_open"] == pytest.approx(1 / 48)  # 180 degrees at 24 fps
    assert meta["variant"] in ("llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb")
    assert frame.header["timeCode"].seconds == 0 and frame.header["timeCode"].frame == 12
    assert frame.header["compression"].name == "ZIP_COMPRESSION"
    assert frame.rgba.dtype == np.float32  # read back as float from half


def test_unknown_preset_is_a_clear_error(tmp_path: Path) -> None:
    proc = run_motion("render", str(SCENES / "cannonball.yaml"), "--preset", "nightly", "-o", str(tmp_path))
    assert proc.returncode == 2
    assert "unknown preset 'nightly'" in proc.stderr and "ci-smoke" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_cli_flag_beats_preset_beats_scene(tmp_path: Path) -> None:
    proc = run_motion("render", str(SCENES / "cannonball.yaml"), "--preset", "ci-smoke", "--resolution", "20x10", "--frames", "0", "-o", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(tmp_path / "cannonball.0000.exr")
    assert frame.rgba.shape == (10, 20, 4)  # CLI flag over the preset's 64x36
    assert frame.meta["spp"] == 4  # preset over the scene's 16


@pytest.mark.render
def test_make_render_twice_with_the_readmes_smoke_args(tmp_path: Path) -> None:
    """The README's `make render ARGS="--preset ci-smoke -o DIR"`, twice: both exit 0, the
    second renders nothing, and the paths printed are the true ones under DIR (before:
    exit 2 on the gaps, then paths under out/cannonball-splash echoed anyway)."""
    out = tmp_path / "smoke"
    env = {**os.environ, "MAKEFLAGS": ""}
    cmd = ["make", "-s", "-C", str(ROOT), "render", f"ARGS=--preset ci-smoke --resolution 32x18 --spp 1 -o {out} --no-progress"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert first.returncode == 0, first.stdout + first.stderr
    assert len(frames_in(out)) == 3
    assert f"frames: {out}/cannonball-splash.0000.exr" in first.stderr
    assert "out/cannonball-splash" not in (first.stdout + first.stderr).replace(str(out), "")
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert second.returncode == 0, second.stdout + second.stderr
    assert "0 rendered, 3 skipped" in second.stderr and "contact: up to date" in second.stderr
