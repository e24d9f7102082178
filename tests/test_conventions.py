"""Scripting conventions (issue 16): --dry-run, --json, -v/-q through logging, a timecode
track in movies, chromaticities and a portable scene path in EXRs, energy plots per body
with a stated zero."""

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


def test_dry_run_plans_and_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = motion("render", SCENE, "-o", out, "--frames", "0-9", "--workers", "2", "--deliver", "24p,contact", "--deliver-frames", "0-9", "--dry-run")
    assert res.returncode == 0, res.stderr
    assert "nothing rendered (--dry-run)" in res.stdout and "to render: 0-9 in" in res.stdout and "farm-tiny_24p_0-9_v001.mov" in res.stdout
    assert not out.exists()
    res = motion("render", SCENE, "-o", out, "--frames", "0-9", "--workers", "2", "--chunk-size", "3", "--dry-run", "--json")
    plan = json.loads(res.stdout)
    assert plan["dry_run"] and plan["to_render"] == "0-9" and plan["chunks"] == ["0-2", "3-5", "6-8", "9"]
    assert plan["executor"] == {"kind": "local", "workers": 2, "threads": 1, "scheduler": None}
    assert plan["outputs"]["first_frame"] == str(out / "farm-tiny.0000.exr") and not out.exists()


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


def test_energy_per_body_with_its_zero_at_height_0(tmp_path: Path) -> None:
    from _dynamics_scenes import ball, floor, write_scene

    from motion.pipeline.dynamics import simulate
    from motion.pipeline.scene import load_scene

    path = write_scene(tmp_path, [ball("a", 2.0, mass=0.5), ball("b", 1.0, x=1.0, mass=2.0), floor(restitution=0.5)], {"integrator": "rk4", "step": 0.002})
    sim = simulate(load_scene(path), 0.3)  # before either lands
    energies = {name: (k, p) for name, _, k, p in sim.body_energy()}
    assert set(energies) == {"a", "b"}
    for name, m, h in (("a", 0.5, 2.0), ("b", 2.0, 1.0)):
        k, p = energies[name]
        assert p[0] == pytest.approx(m * 9.81 * h) and np.allclose(k + p, m * 9.81 * h, rtol=1e-9)
    res = motion("plot", path, "--what", "energy", "-o", tmp_path / "e.png")
    assert res.returncode == 0 and (tmp_path / "e.png").stat().st_size > 10_000, res.stderr
