"""The run report (farm/report.py) as a disk holds it: a damaged one is discarded with one
warning and rebuilt."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import motion, report


DAMAGED_REPORTS = {
    "wrong-types": json.dumps({"scene_name": "s", "run_id": "r", "frames": [{"frame": [1], "status": "rendered"}], "history": 5}),
    "row-field-wrong-type": json.dumps({"scene_name": "s", "run_id": "r", "frames": [{"frame": 0, "status": "rendered", "render_s": {"x": 1}}]}),
    "not-an-object": "[1, 2, 3]",
    "deep-nesting": '{"scene_name": "s", "history": [' + "[" * 100_000 + "]" * 100_000 + "]}",
    "nested-history": json.dumps({"scene_name": "s", "history": [{"totals": {"a": [[[]]]}}]}),
    "not-utf8": "\udcff",
    "fifo": None,
}


@pytest.mark.parametrize("case", sorted(DAMAGED_REPORTS))
def test_a_damaged_report_is_discarded_with_one_warning_and_rebuilt(tmp_path: Path, case: str) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    out = tmp_path / "out"
    out.mkdir()
    body = DAMAGED_REPORTS[case]
    if body is None:
        os.mkfifo(out / "render-report.json")
    else:
        (out / "render-report.json").write_bytes(body.encode("utf-8", "surrogateescape"))
    res = motion("render", scene, "-o", out, timeout=120)  # before: a traceback after every frame (a FIFO: hung)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    warnings = [line for line in res.stderr.splitlines() if "render-report.json" in line and "warning" in line]
    assert len(warnings) == 1 and "a new report is written" in warnings[0], res.stderr
    rep = report(out)
    assert rep["totals"]["rendered"] == 2 and rep["history"] == [] and rep["folder"]["count"] == 2
