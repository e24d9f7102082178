"""Honest status (issue 16): the bake says how fast it simulates, progress moves per
frame, interrupted frames are "not rendered" (never "failed"), and every `--deliver`
check that can fail runs before the first frame is rendered."""

from __future__ import annotations

import io
import logging
import signal
import threading

import pytest

from farm_util import SCENE, SLOW, TINY, frames_in, motion, report, start_motion, wait_for
from motion.pipeline.farm.progress import BakeProgress

LINES = [a for a in TINY if a != "--no-progress"]  # stderr is not a terminal: plain progress lines


def test_bake_progress_reports_simulated_seconds_per_second_and_eta(caplog) -> None:
    caplog.set_level(logging.INFO, logger="motion")
    shown = BakeProgress(stream=io.StringIO(), live=None, every_s=0.0)  # not a terminal: plain lines
    for k in range(1, 5):
        shown.simulated(k * 0.5, 0.0, 4.0)
    shown.baked(96)
    lines = [r.getMessage() for r in caplog.records]
    assert "bake: simulated 2.00 of 4.00 s" in lines[-2] and "simulated s per s, ETA" in lines[-2]
    assert lines[-1].startswith("motion: bake: simulated 2.00 s of dynamics in") and lines[-1].endswith("96 frames baked in " + lines[-1].rsplit(" in ", 1)[1])


def test_render_prints_the_bake_rate(tmp_path, monkeypatch) -> None:
    from test_range_independence import _scene

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))  # a root of its own: no simulation kept by another test

    res = motion("render", _scene(tmp_path), "-o", tmp_path / "out", "--frames", "0-1", *LINES, "--workers", "1")
    assert res.returncode == 0, res.stderr
    line = next(l for l in res.stderr.splitlines() if l.startswith("motion: bake:"))
    # the whole timeline is simulated (frame 0 opens at -1/96 s, frame 47 closes at 47/24 + 1/96 s), not 2 frames
    assert "simulated 1.98 s" in line and "simulated s per s" in line and "2 frames baked" in line


def test_progress_is_per_frame_and_interrupted_frames_are_not_rendered(tmp_path) -> None:
    """One chunk of 14 frames: progress reports its first frame while the chunk still runs
    (a worker reports each finished frame); after Ctrl-C the frames on disk are rendered
    and the rest are "not rendered", none "failed"."""
    out = tmp_path / "out"
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-13", "--workers", "1", "--chunk-size", "14", *[a for a in SLOW if a != "--no-progress"])
    lines: list[str] = []
    seen_at: list[int] = []

    def read() -> None:
        for line in proc.stderr:
            if line.startswith("  farm-tiny: ") and "/14 frames" in line and not seen_at:
                seen_at.append(len(frames_in(out)))
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    wait_for(lambda: bool(seen_at), 60, "a progress line")
    assert seen_at[0] < 14 and proc.poll() is None  # reported before the chunk came back
    wait_for(lambda: len(frames_in(out)) >= 3, 60, "some frames")
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    reader.join(10)
    stderr = "".join(lines)
    assert proc.returncode == 130, stderr
    rep = report(out)
    on_disk = {int(p.name.split(".")[1]) for p in frames_in(out)}
    status = {r["frame"]: r["status"] for r in rep["frames"]}
    assert rep["interrupted"] and rep["failed"] == [] and rep["totals"]["failed"] == 0
    assert {f for f, s in status.items() if s == "rendered"} == on_disk  # written before the stop: rendered
    assert {f for f, s in status.items() if s == "not_rendered"} == set(range(14)) - on_disk
    assert rep["totals"]["not_rendered"] == 14 - len(on_disk)
    # frames written before the stop carry their render time from their own header (0.0 before)
    assert rep["totals"]["render_s_sum"] > 0 and all(r.get("render_s", 0) > 0 for r in rep["frames"] if r["status"] == "rendered")
    assert "FAILED" not in stderr and f"{14 - len(on_disk)} not rendered (interrupted)" in stderr


@pytest.mark.parametrize(
    "args,message",
    [
        (["--preset", "ci-smoke", "--deliver", "24p"], "gapless"),  # ci-smoke spreads 3 frames over the timeline
        (["--frames", "0-3", "--resolution", "16x11", "--deliver", "60i"], "even height"),
        (["--frames", "0-3", "--deliver", "24p", "--ocio", "/no/such/config.ocio"], "config"),
    ],
)
def test_every_deliver_check_runs_before_the_first_frame(tmp_path, args, message) -> None:
    res = motion("render", SCENE, "-o", tmp_path, "--no-progress", *args)
    assert res.returncode == 2, res.stderr
    assert message in res.stderr and "Traceback" not in res.stderr
    assert frames_in(tmp_path) == []
