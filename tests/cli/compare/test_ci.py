"""The compare recipe of docs/ci-sharding.md ("Checking the pictures"), run locally from the
doc's own workflow: two shard jobs render, the compare job gathers their frames and compares
them with the repository's golden set, and publishes the report."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from farm_util import MOTION, ROOT

pytestmark = pytest.mark.render


def _workflow() -> dict:
    text = (ROOT / "docs" / "ci-sharding.md").read_text()
    section = text[text.index("## Checking the pictures"):]
    block = re.search(r"```yaml\n(.*?)```", section, re.S)
    assert block, "the compare recipe has no yaml block"
    return yaml.safe_load(block.group(1))


def _run(steps: list[dict], cwd: Path, env: dict[str, str], matrix: dict[str, str]) -> list[subprocess.CompletedProcess]:
    out = []
    for step in steps:
        if "run" not in step or step["run"].startswith("pip install"):
            continue
        script = step["run"]
        for key, value in matrix.items():
            script = script.replace("${{ matrix.%s }}" % key, str(value))
        assert "${{" not in script, script
        out.append(subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=cwd, env=env, capture_output=True, text=True, timeout=300))
    return out


def test_compare_recipe_renders_gathers_compares_and_reports(tmp_path: Path) -> None:
    wf = _workflow()
    env = {**os.environ, **{k: str(v) for k, v in wf["env"].items()}, "PATH": f"{Path(MOTION).parent}:{os.environ['PATH']}"}
    env["SCENE"] = str(ROOT / wf["env"]["SCENE"])
    env["GOLDEN"] = str(ROOT / wf["env"]["GOLDEN"])
    gather = tmp_path / "compare"
    (gather / "frames").mkdir(parents=True)
    shards = wf["jobs"]["render"]["strategy"]["matrix"]["shard"]
    assert len(shards) == int(wf["env"]["SHARDS"])
    for shard in shards:
        runner = tmp_path / f"shard{shard}"
        runner.mkdir()
        for res in _run(wf["jobs"]["render"]["steps"], runner, env, {"shard": shard}):
            assert res.returncode == 0, res.stderr
        for p in (runner / "frames").iterdir():  # upload/download-artifact: merged, hidden files left
            if not p.name.startswith("."):
                shutil.copy2(p, gather / "frames" / p.name)
    (res,) = _run(wf["jobs"]["compare"]["steps"], gather, env, {})
    assert res.returncode == 0, res.stdout + res.stderr
    assert "PASS: 3 frames" in res.stdout
    report = gather / "compare-report"
    assert (report / "index.html").is_file() and (report / "junit.xml").is_file() and (report / "compare.json").is_file()
