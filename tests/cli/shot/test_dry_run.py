"""The dry run (shot/dry_run.py): it plans and writes nothing, and shows the resolved
settings with their source and an estimate."""

from __future__ import annotations

import json
from pathlib import Path

from farm_util import SCENE, motion


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


def test_the_dry_run_shows_resolved_settings_with_their_source_and_an_estimate(tmp_path: Path) -> None:
    res = motion("render", SCENE, "-o", tmp_path / "out", "--preset", "ci-smoke", "--spp", "3", "--frames", "0-3", "--dry-run", "--json")
    assert res.returncode == 0, res.stderr
    plan = json.loads(res.stdout)
    s = plan["settings"]
    assert s["spp"] == {"value": 3, "from": "flag"}
    assert s["resolution"] == {"value": [64, 36], "from": "preset ci-smoke"}
    assert s["max_depth"]["from"] == "preset ci-smoke" and s["motion_blur"]["from"] == "default"
    assert plan["estimate"]["seconds"] > 0 and plan["estimate"]["basis"]
    text = motion("render", SCENE, "-o", tmp_path / "out", "--preset", "final", "--frames", "0-3", "--dry-run").stdout
    assert "resolution 1920x1080 (preset final)" in text and "estimate:" in text
