"""The CI sharding recipe of docs/ci-sharding.md, run locally from the doc's own workflow,
and determinism: frames from 1 worker, 2 workers and 3 shards are bit-identical."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from farm_util import MOTION, ROOT, SCENE, frames_in, motion, report
from motion.pipeline.frame_output import read_frame

pytestmark = pytest.mark.render

FRAMES = "0-11"


def _workflow() -> dict:
    text = (ROOT / "docs" / "ci-sharding.md").read_text()
    block = re.search(r"```yaml\n(.*?)```", text, re.S)
    assert block, "docs/ci-sharding.md has no yaml block"
    return yaml.safe_load(block.group(1))


def _run_steps(steps: list[dict], cwd: Path, env: dict[str, str], matrix: dict[str, str]) -> None:
    """Run a job's `run:` steps with bash, as a runner would (matrix filled in)."""
    for step in steps:
        if "run" not in step:
            continue
        script = step["run"]
        for key, value in matrix.items():
            script = script.replace("${{ matrix.%s }}" % key, str(value))
        assert "${{" not in script, f"unfilled expression in {script!r}"
        proc = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=cwd, env=env, capture_output=True, text=True, timeout=180)
        if step.get("run", "").startswith("pip install"):
            continue
        assert proc.returncode == 0, f"{step.get('name', script)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"


@pytest.fixture(scope="module")
def ci_run(tmp_path_factory) -> dict[str, Path]:
    """Every shard job in its own folder (a runner each), then the gather job."""
    base = tmp_path_factory.mktemp("ci")
    wf = _workflow()
    env = {**os.environ, **{k: str(v) for k, v in wf["env"].items()}}
    env.update(SCENE=str(SCENE), FRAMES=FRAMES, PATH=f"{Path(MOTION).parent}:{os.environ['PATH']}")
    render_steps = [s for s in wf["jobs"]["render"]["steps"] if "run" in s and "pip install" not in s["run"]]
    shards = wf["jobs"]["render"]["strategy"]["matrix"]["shard"]
    assert len(shards) == int(wf["env"]["SHARDS"])
    gather = base / "gather"
    (gather / "frames").mkdir(parents=True)
    for shard in shards:
        runner = base / f"shard{shard}"
        runner.mkdir()
        _run_steps(render_steps, runner, env, {"shard": shard})
        # upload/download-artifact: the non-hidden files of frames/, merged
        for p in (runner / "frames").iterdir():
            if not p.name.startswith("."):
                shutil.copy2(p, gather / "frames" / p.name)
    gather_steps = [s for s in wf["jobs"]["gather"]["steps"] if "run" in s and "pip install" not in s["run"]]
    _run_steps(gather_steps, gather, env, {})
    return {"base": base, "gather": gather, "env": env}


def test_ci_recipe_shards_and_gather(ci_run) -> None:
    gather = ci_run["gather"]
    frames = frames_in(gather / "frames")
    assert [int(p.name.split(".")[1]) for p in frames] == list(range(12))
    reports = [report(gather / "frames", f"render-report.shard-{i}-of-3.json") for i in (1, 2, 3)]
    assert [r["frames_this_job"] for r in reports] == ["0-3", "4-7", "8-11"]
    assert sum(r["totals"]["rendered"] for r in reports) == 12
    # the gather step's `--check --deliver` assembled from the complete frames (issue 23)
    deliver = gather / "frames" / "deliver"
    assert (deliver / "60i_0-11_v001").is_dir() and list((deliver / "60i_0-11_v001").glob("*.exr"))
    assert (deliver / "farm-tiny_contact_0-11_v001.png").stat().st_size > 0 and (deliver / "farm-tiny_24p_0-11_v001.mov").stat().st_size > 0
    made = json.loads((deliver / "manifest.json").read_text())["deliverables"]
    assert set(made) == {"24p@0-11", "60i@0-11", "contact@0-11"} and all(m["versions"]["v001"]["frames"] == "0-11" for m in made.values())


def test_ci_gather_check_fails_on_a_missing_frame(ci_run, tmp_path) -> None:
    partial = tmp_path / "frames"
    shutil.copytree(ci_run["gather"] / "frames", partial, ignore=shutil.ignore_patterns("deliver"))
    (partial / "farm-tiny.0005.exr").unlink()
    res = motion("render", SCENE, "--preset", "ci-smoke", "--frames", FRAMES, "-o", partial, "--check")
    assert res.returncode == 3, res.stderr
    assert "missing 5" in res.stderr
    # with --deliver: exit 3 and no deliver folder made (it was left empty before, exit 0)
    res = motion("render", SCENE, "--preset", "ci-smoke", "--frames", FRAMES, "-o", partial, "--check", "--deliver", "24p,contact", "--deliver-frames", FRAMES)
    assert res.returncode == 3 and "missing 5" in res.stderr, res.stderr
    assert not (partial / "deliver").exists()


def test_one_worker_two_workers_three_shards_bit_identical(ci_run, tmp_path) -> None:
    outs = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        res = motion("render", SCENE, "--preset", "ci-smoke", "--frames", FRAMES, "-o", out, "--workers", workers, "--no-progress")
        assert res.returncode == 0, res.stderr
        outs[workers] = out
    assert len({r["worker"] for r in report(outs[2])["frames"]}) == 2  # both workers rendered
    # a small job renders in this process (farm/inline.py): the same pixels (issue 28)
    inline = tmp_path / "inline"
    res = subprocess.run([MOTION, "render", str(SCENE), "--preset", "ci-smoke", "--frames", FRAMES, "-o", str(inline), "--no-progress"],
                         capture_output=True, text=True, timeout=300, env={**os.environ, "MOTION_EXECUTOR": "inline"})
    assert res.returncode == 0, res.stderr
    assert report(inline)["executor"]["kind"] == "inline"
    sharded = ci_run["gather"] / "frames"
    for f in range(12):
        name = f"farm-tiny.{f:04d}.exr"
        a, b, c, d = (read_frame(folder / name) for folder in (outs[1], outs[2], sharded, inline))
        assert a.rgba.shape == (36, 64, 4)
        assert np.array_equal(a.rgba, b.rgba) and np.array_equal(a.rgba, c.rgba) and np.array_equal(a.rgba, d.rgba), f"frame {f} differs"
        assert a.meta["motion_hash"] == b.meta["motion_hash"] == c.meta["motion_hash"] == d.meta["motion_hash"]
        assert a.meta["settings_hash"] == c.meta["settings_hash"]
    assert len({read_frame(outs[1] / f"farm-tiny.{f:04d}.exr").rgba.tobytes() for f in range(12)}) == 12  # frames differ
