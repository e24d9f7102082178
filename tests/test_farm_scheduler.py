"""The farm's decisions in process (issue 26): retries elsewhere, exclusion, timeouts, disk
faults, workers running out and interrupts, driven through the real `Scheduler` by a
scripted executor (each worker's outcome per chunk written down in advance) and a clock
the test moves. Milliseconds each; tests/test_farm_local.py keeps the end-to-end checks
with real processes and signals."""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Sequence

import pytest

from motion.pipeline.farm.config import FarmConfig
from motion.pipeline.farm.executor import Done, Event, FrameWritten, Lost
from motion.pipeline.farm.scheduler import Scheduler
from motion.pipeline.farm.task import ChunkResult, TaskContext
from motion.pipeline.render.job import FrameResult, RenderJob

JOB = RenderJob(scene_path="x.yaml", overrides={}, output_dir="out", scene_hash="s", settings_hash="h")


class Clock:
    """Seconds that pass only when the test (or the script) says so."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class Scripted:
    """An executor whose workers do what the script says, chunk by chunk: 'ok', 'fail',
    'lost', 'hang' (never answers), 'disk' (the disk refused the first frame's write)."""

    kind = "scripted"

    def __init__(self, script: dict[str, list[str]], clock: Clock, grow: bool = False) -> None:
        self.script = {w: deque(steps) for w, steps in script.items()}
        self.clock = clock
        self.grow = grow
        self.busy: dict[str, tuple[int, list[int], str]] = {}
        self.stopped: list[tuple[str, str]] = []
        self.submitted: list[tuple[str, list[int]]] = []
        self.contexts: list[TaskContext] = []

    def idle_workers(self) -> list[str]:
        return [w for w in self.script if w not in self.busy]

    def live_workers(self) -> list[str]:
        return list(self.script)

    def can_grow(self) -> bool:
        return self.grow

    def submit(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[object], ctx: TaskContext) -> None:
        frames = [fi.frame for fi in inputs]  # type: ignore[attr-defined]
        step = self.script[worker].popleft() if self.script[worker] else "ok"
        self.busy[worker] = (chunk_id, frames, step)
        self.submitted.append((worker, frames))
        self.contexts.append(ctx)

    def poll(self, timeout: float) -> list[Event]:
        self.clock.t += timeout
        events: list[Event] = []
        for worker, (chunk_id, frames, step) in list(self.busy.items()):
            if step == "hang":
                continue
            del self.busy[worker]
            if step == "lost":
                events.append(Lost(worker, chunk_id, f"worker {worker} died (signal 9)"))
                continue
            res = ChunkResult(chunk_id=chunk_id, worker=worker)
            for k, f in enumerate(frames):
                if step == "disk" and k == 0:
                    res.results.append(FrameResult(f, "", False, worker, error="no space left on device: out/f", disk_fault=True))
                    res.disk_fault = "no space left on device: out/f"
                    break
                ok = step != "fail"
                res.results.append(FrameResult(f, f"out/{f}.exr" if ok else "", ok, worker, cold=k == 0, render_s=0.1, error=None if ok else "boom"))
                if ok:
                    events.append(FrameWritten(worker, chunk_id, f, 0.1))
            events.append(Done(worker, chunk_id, res))
        return events

    def stop_worker(self, worker: str, reason: str) -> None:
        self.stopped.append((worker, reason))
        self.busy.pop(worker, None)
        if not self.grow:
            self.script.pop(worker, None)

    def close(self, interrupted: bool = False) -> None:
        pass


class Frame:
    def __init__(self, frame: int) -> None:
        self.frame = frame


def run(tmp_path: Path, script: dict[str, list[str]], chunks: list[list[int]], **cfg: float) -> tuple[Scheduler, Scripted, list[tuple[str, dict]]]:
    clock = Clock()
    ex = Scripted(script, clock, grow=bool(cfg.pop("grow", False)))
    frames = [f for c in chunks for f in c]
    ctx = TaskContext(run_id="r", paths={f: str(tmp_path / f"f.{f:04d}.exr") for f in frames})
    seen: list[tuple[str, dict]] = []
    sched = Scheduler(ex, JOB, {f: Frame(f) for f in frames}, ctx, FarmConfig(**cfg), notify=lambda k, d: seen.append((k, d)),  # type: ignore[arg-type]
                      no_worker_grace_s=5.0, poll_s=0.5, clock=clock)
    sched.run(chunks)
    return sched, ex, seen


def status(sched: Scheduler) -> dict[int, str]:
    return {f: r.status for f, r in sched.frames.items()}


def test_a_task_carries_the_paths_of_its_own_frames_only(tmp_path: Path) -> None:
    """What travels with a task is O(its frames), not O(the job's frames): the whole job's
    paths in every task made a 100,000-frame job send 7 MB a task."""
    chunks = [[f, f + 1] for f in range(0, 400, 2)]
    sched, ex, _ = run(tmp_path, {"a": [], "b": []}, chunks)
    assert set(status(sched).values()) == {"rendered"} and len(ex.contexts) == 200
    for (_, frames), ctx in zip(ex.submitted, ex.contexts):
        assert ctx.paths == {f: str(tmp_path / f"f.{f:04d}.exr") for f in frames}
        assert ctx.run_id == "r"


def test_a_failed_chunk_is_retried_on_another_worker(tmp_path: Path) -> None:
    sched, ex, seen = run(tmp_path, {"a": ["fail"], "b": ["ok", "ok"]}, [[0, 1], [2, 3]], retries=2)
    assert status(sched) == {0: "rendered", 1: "rendered", 2: "rendered", 3: "rendered"}
    assert [w for w, fs in ex.submitted if fs == [0, 1]] == ["a", "b"]  # not back on a
    assert sched.frames[0].attempts == 2 and sched.frames[0].errors == ["boom"]
    assert ("retry", {"frames": [0, 1], "worker": "a", "error": "boom", "attempt": 1}) in seen


def test_retries_run_out_and_the_frames_fail_with_the_last_error(tmp_path: Path) -> None:
    sched, _, seen = run(tmp_path, {"a": ["fail"] * 5, "b": ["fail"] * 5}, [[0]], retries=1, max_worker_failures=10)
    assert status(sched) == {0: "failed"} and sched.frames[0].attempts == 2
    assert ("failed", {"frame": 0, "error": "boom"}) in seen


def test_a_worker_that_keeps_failing_is_excluded_and_the_others_finish(tmp_path: Path) -> None:
    sched, ex, _ = run(tmp_path, {"bad": ["fail"] * 9, "good": []}, [[f] for f in range(6)], retries=5, max_worker_failures=2)
    assert set(status(sched).values()) == {"rendered"}
    assert "bad" in sched.excluded and ("bad", "excluded") in ex.stopped
    assert sched.workers["bad"].failures == 2 and sched.workers["bad"].excluded


def test_a_chunk_past_its_timeout_is_stopped_and_retried(tmp_path: Path) -> None:
    sched, ex, _ = run(tmp_path, {"slow": ["hang"], "fast": []}, [[0, 1], [2]], task_timeout_s=30.0, retries=1, grow=True)
    assert set(status(sched).values()) == {"rendered"}
    assert ("slow", "timeout") in ex.stopped
    assert any("timed out after 30s on slow" in e for e in sched.frames[0].errors)


def test_a_lost_worker_costs_a_retry_elsewhere(tmp_path: Path) -> None:
    sched, _, _ = run(tmp_path, {"a": ["lost"], "b": []}, [[0, 1, 2]], retries=1)
    assert set(status(sched).values()) == {"rendered"}
    assert sched.workers["a"].lost == ["worker a died (signal 9)"]


def test_a_disk_fault_stops_the_job_and_blames_nobody(tmp_path: Path) -> None:
    sched, ex, seen = run(tmp_path, {"a": ["disk"], "b": ["ok"]}, [[0, 1], [2, 3], [4, 5]], retries=3)
    assert sched.disk_fault == "no space left on device: out/f"
    assert not sched.excluded and not ex.stopped
    assert ("disk_fault", {"worker": "a", "error": "no space left on device: out/f"}) in seen
    st = status(sched)
    assert st[0] == "failed" and st[2] == st[3] == "rendered"  # the running chunk came back on its own
    assert st[4] == st[5] == "pending"  # the queued chunk never started
    assert any("stopped on a disk fault" in e for e in sched.frames[4].errors)
    assert not [k for k, _ in seen if k == "retry"]


def test_no_usable_worker_left_fails_the_rest_with_why(tmp_path: Path) -> None:
    sched, _, _ = run(tmp_path, {"a": ["fail"] * 9}, [[0], [1], [2]], retries=5, max_worker_failures=1)
    assert set(status(sched).values()) == {"failed"}
    assert "no usable workers left (1 excluded after repeated failures)" in sched.frames[2].errors[-1]


def test_an_interrupt_settles_unfinished_frames_as_not_rendered(tmp_path: Path) -> None:
    clock = Clock()
    ex = Scripted({"a": ["hang"]}, clock)
    ctx = TaskContext(run_id="r", paths={f: str(tmp_path / f"f.{f:04d}.exr") for f in (0, 1)})
    from farm_util import SCENE
    from motion.pipeline.bake import bake
    from motion.pipeline.scene import load_scene

    baked = bake(load_scene(SCENE), [0, 1])  # settle_interrupted reads each frame's expected hashes
    sched = Scheduler(ex, JOB, {f: baked.frame(f) for f in (0, 1)}, ctx, FarmConfig(), poll_s=0.5, clock=clock)

    def interrupt(timeout: float) -> list[Event]:
        raise KeyboardInterrupt

    ex.poll = interrupt  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        sched.run([[0, 1]])
    assert sched.abandon() == [0, 1]
    assert sched.settle_interrupted() == ([], [0, 1])
    assert status(sched) == {0: "not_rendered", 1: "not_rendered"}


def test_frame_states_are_a_closed_set_moved_only_by_the_transitions_table() -> None:
    """A frame's state moves only along TRANSITIONS: a final state never moves again, every
    state in the table is one of FRAME_STATES, and the scheduler assigns no status by hand."""
    import re

    from motion.pipeline.farm import scheduler
    from motion.pipeline.farm.scheduler import FRAME_STATES, TRANSITIONS, FrameRecord

    assert {s for move in TRANSITIONS for s in move} <= set(FRAME_STATES)
    rec = FrameRecord(7)
    rec.move("rendered")
    assert rec.status == "rendered"
    with pytest.raises(RuntimeError, match="frame 7: no move from 'rendered' to 'failed'"):
        rec.move("failed")
    source = Path(scheduler.__file__).read_text()
    assigned = re.findall(r"\.status\s*=[^=]", source)
    assert len(assigned) == 1, "only FrameRecord.move assigns a status"
