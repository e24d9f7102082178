"""Progress (farm/progress.py): the bake's simulated seconds per second, an ETA measured from
the first frame done, a healthy bar."""

from __future__ import annotations

import io
import logging
import time
from pathlib import Path

import pytest

from motion.pipeline.farm.progress import Progress
from motion.pipeline.farm.progress import BakeProgress


def test_the_eta_is_measured_from_the_first_frame_done(monkeypatch: pytest.MonkeyPatch) -> None:
    """Start-up and cold frames do not inflate the ETA: 10 frames, the first done at 5 s
    (cold), then one every 0.5 s: the ETA after 3 frames is 7 x 0.5 s, not 7 x 5/3 s."""
    clock = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    p = Progress(total=10, stream=io.StringIO(), live=False, estimate_s=0.6)
    assert p.eta_s == pytest.approx(6.0)  # the plan's estimate before two frames are done
    for frame, t in ((0, 105.0), (1, 105.5), (2, 106.0)):
        clock[0] = t
        p.event("written", {"frame": frame, "worker": "w", "seconds": 0.5, "path": f"f{frame}"})
    assert p.eta_s == pytest.approx(3.5)


def test_a_healthy_bar_is_green(tmp_path: Path) -> None:
    logging.getLogger("motion").setLevel(logging.INFO)
    with Progress(total=2, stream=io.StringIO(), live=True) as p:
        assert p._bar.columns[1].complete_style == "green"
        p.event("failed", {"frame": 0, "error": "x"})
        assert p._bar.columns[1].complete_style == "red"


def test_bake_progress_reports_simulated_seconds_per_second_and_eta(caplog) -> None:
    caplog.set_level(logging.INFO, logger="motion")
    shown = BakeProgress(stream=io.StringIO(), live=None, every_s=0.0)  # not a terminal: plain lines
    for k in range(1, 5):
        shown.simulated(k * 0.5, 0.0, 4.0)
    shown.baked(96)
    lines = [r.getMessage() for r in caplog.records]
    assert "bake: simulated 2.00 of 4.00 s" in lines[-2] and "simulated s per s, ETA" in lines[-2]
    assert lines[-1].startswith("motion: bake: simulated 2.00 s of dynamics in") and lines[-1].endswith("96 frames baked in " + lines[-1].rsplit(" in ", 1)[1])
