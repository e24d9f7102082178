"""A render interrupted by a signal (SIGINT, SIGTERM): the frames in flight are "not rendered",
never "failed", and the exit status is the shell's."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

from farm_util import SCENE, SLOW, frames_in, leftovers, report, start_motion, wait_for, worker_pids
from motion.pipeline.frame_output import is_complete


def _alive(pid: int) -> bool:
    """Whether `pid` is a live process (a zombie is not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def test_sigterm_ends_a_render_like_ctrl_c_with_exit_143(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-13", "--workers", "2", "--chunk-size", "2", *SLOW)
    wait_for(lambda: len(frames_in(out)) >= 1, 60, "a first frame")
    workers = worker_pids(proc.pid)
    assert workers
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, (proc.returncode, stderr)  # before: killed by the signal (-15), no report
    assert stderr.strip().splitlines()[-1] == "terminated" and "Traceback" not in stderr
    rep = report(out)
    assert rep["interrupted"] is True
    wait_for(lambda: not any(_alive(p) for p in workers), 10, "the workers to stop")
    done = {p.name for p in frames_in(out)}
    time.sleep(1.0)
    assert {p.name for p in frames_in(out)} == done  # no worker writes on after the stop
    assert all(is_complete(out / name) for name in done) and 1 <= len(done) < 14
    assert not leftovers(out)  # no partial files, no claims, no run lock


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
