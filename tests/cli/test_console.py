"""What the command prints and records: --json summaries, -v/-q through logging, progress
lines when stderr is not a terminal; and, on the same rendered job, the EXRs'
chromaticities and portable scene path and the movie's timecode track."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import av
import numpy as np
import pytest

from farm_util import SCENE, TINY, motion
from motion.pipeline.frame_output import REC709_CHROMATICITIES, read_frame


@pytest.fixture(scope="module")
def job(tmp_path_factory) -> tuple[Path, Path, object]:
    """farm-tiny copied beside its output folder; frames 5-9 rendered with -v, --json and a 24p movie."""
    root = tmp_path_factory.mktemp("conv")
    scene = root / "farm-tiny.yaml"
    shutil.copy(SCENE, scene)
    res = motion("-v", "render", scene, "-o", root / "out", "--frames", "5-9", *TINY, "--workers", "1", "--chunk-size", "5", "--deliver", "24p", "--deliver-frames", "5-9", "--json")
    assert res.returncode == 0, res.stderr
    return root, scene, res


def test_render_json_summary_and_verbose_log(job) -> None:
    root, _, res = job
    summary = json.loads(res.stdout)
    assert summary["totals"]["rendered"] == 5 and summary["report"] == str(root / "out" / "render-report.json")
    assert summary["deliverables"]["24p"] == [str(root / "out" / "deliver" / "farm-tiny_24p_5-9_v001.mov")]
    assert all(f"frame {f}: {root / 'out' / f'farm-tiny.{f:04d}.exr'} in " in res.stderr for f in range(5, 10))  # -v: each frame's path and time


def test_quiet_keeps_stderr_to_warnings(tmp_path: Path) -> None:
    res = motion("-q", "render", SCENE, "-o", tmp_path, "--frames", "0-1", *TINY)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert len(list(tmp_path.glob("*.exr"))) == 2


def test_validate_json(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(SCENE.read_text().replace("fov: 40", "fov: -40"))
    res = motion("validate", SCENE, bad, "--json")
    assert res.returncode == 2
    doc = json.loads(res.stdout)
    assert doc["ok"] is False and [s["ok"] for s in doc["scenes"]] == [True, False]
    assert doc["scenes"][0]["frames"] == [0, 47]
    problem = doc["scenes"][1]["problems"][0]
    assert problem["file"].endswith("bad.yaml") and problem["line"] and "fov" in problem["yaml_path"]
    assert str(bad) in res.stderr  # the one-line problem still goes to stderr


def test_exr_chromaticities_and_relative_scene_path(job) -> None:
    root, _, _ = job
    frame = read_frame(root / "out" / "farm-tiny.0005.exr")
    assert np.allclose(frame.header["chromaticities"], REC709_CHROMATICITIES, atol=1e-6)
    assert frame.meta["scene"] == "../farm-tiny.yaml"


def test_movie_has_a_timecode_track_from_the_frames(job) -> None:
    root, _, _ = job
    with av.open(str(root / "out" / "deliver" / "farm-tiny_24p_5-9_v001.mov")) as movie:
        data = [s for s in movie.streams if s.type == "data"]
        assert data and data[0].metadata.get("timecode") == "00:00:00:05"  # the first frame is 5 at 24 fps


LINES = [a for a in TINY if a != "--no-progress"]  # stderr is not a terminal: plain progress lines


def test_verbose_says_each_frame_path_and_time_and_no_progress_is_quiet(tmp_path: Path) -> None:
    out = tmp_path / "v"
    res = motion("-v", "render", SCENE, "-o", out, "--frames", "0-2", *LINES, "--workers", "1")
    assert res.returncode == 0, res.stderr
    for f in range(3):
        path = out / f"farm-tiny.{f:04d}.exr"
        assert any(line.startswith(f"  frame {f}: {path} in ") for line in res.stderr.splitlines()), res.stderr
    quiet = motion("render", SCENE, "-o", tmp_path / "q", "--frames", "0-5", *TINY, "--workers", "1")
    assert quiet.returncode == 0, quiet.stderr
    lines = quiet.stderr.splitlines()
    assert not [line for line in lines if "frames/min, 0 failed" in line and "rendered" not in line], lines  # no periodic lines
    assert not [line for line in lines if "bake:" in line or "executor:" in line], lines
    assert any("6 rendered, 0 skipped" in line for line in lines)


def test_render_prints_the_bake_rate(tmp_path, monkeypatch) -> None:
    from tests.bake.test_range_independence import _scene

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))  # a root of its own: no simulation kept by another test

    res = motion("render", _scene(tmp_path), "-o", tmp_path / "out", "--frames", "0-1", *LINES, "--workers", "1")
    assert res.returncode == 0, res.stderr
    line = next(l for l in res.stderr.splitlines() if l.startswith("motion: bake:"))
    # the whole timeline is simulated (frame 0 opens at -1/96 s, frame 47 closes at 47/24 + 1/96 s), not 2 frames
    assert "simulated 1.98 s" in line and "simulated s per s" in line and "2 frames baked" in line
