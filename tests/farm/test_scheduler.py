"""The farm's decisions in process: retries elsewhere, exclusion, timeouts, disk faults,
workers running out and interrupts, driven through the real `Scheduler` by a scripted
executor (each worker's outcome per chunk written down in advance) and a clock the test
moves; then the frame and chunk state machine (`farm/lifecycle.py`) alone, fed events by
hand. Milliseconds each; tests/cli/farm/test_local.py keeps the end-to-end checks with real
processes and signals."""

from __future__ import annotations

from collections import deque
from pathlib import Path
from typing import Sequence

import pytest

from motion.pipeline.farm.config import FarmConfig
from motion.pipeline.farm.executor import Done, Event, FrameWritten, Lost
from motion.pipeline.farm.scheduler import Scheduler
from motion.pipeline.farm.task import ChunkResult, TaskContext
from motion.pipeline.render.worker.job import FrameResult, RenderJob

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
        frames = [baked.frame for baked in inputs]  # type: ignore[attr-defined]
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
    from motion.pipeline.farm.report import _frame_rows, _totals

    rows = _frame_rows([], sched, JOB, None)  # type: ignore[arg-type]
    failed = [r for r in rows if r["status"] in ("failed", "pending")]
    totals = _totals(rows, 6, len(failed), {})
    assert [(k, totals[k]) for k in list(totals)[:6]] == [("frames", 6), ("rendered", 2), ("skipped", 0), ("done_elsewhere", 0), ("failed", 4), ("not_rendered", 0)]


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


# --- the state machine alone: events in, decisions out, no executor and no disk ------------

from motion.pipeline.farm import lifecycle  # noqa: E402
from motion.pipeline.farm.lifecycle import (  # noqa: E402
    CHUNK_TRANSITIONS, FRAME_TRANSITIONS, Chunk, Cleanup, IllegalMove, Lifecycle, Notify, StopWorker, Submit,
)
from motion.pipeline.farm.states import CHUNK_STATES, FINAL_CHUNK_STATES, FINAL_FRAME_STATES, FRAME_STATES  # noqa: E402


def _reachable(start: str, moves: Sequence[tuple[str, str]]) -> set[str]:
    seen, todo = {start}, [start]
    while todo:
        here = todo.pop()
        for a, b in moves:
            if a == here and b not in seen:
                seen.add(b)
                todo.append(b)
    return seen


@pytest.mark.parametrize("states, finals, moves", [(FRAME_STATES, FINAL_FRAME_STATES, FRAME_TRANSITIONS), (CHUNK_STATES, FINAL_CHUNK_STATES, CHUNK_TRANSITIONS)],
                         ids=["frame", "chunk"])
def test_every_state_has_its_moves_listed(states: tuple[str, ...], finals: tuple[str, ...], moves: dict) -> None:
    """The table covers every state: each unfinished state has its moves out, a final state
    none, every state is reached from 'queued', and the table names no other state."""
    assert {s for move in moves for s in move} == set(states)
    for s in states:
        out = {b for a, b in moves if a == s}
        assert bool(out) == (s not in finals), f"{s}: moves out {sorted(out)}"
    assert _reachable("queued", list(moves)) == set(states)
    assert set(finals) < set(states)


def test_a_move_the_tables_do_not_list_raises_and_changes_nothing() -> None:
    m = Lifecycle(FarmConfig())
    m.add([[7]])
    rec = m.frames[7]
    for start in FRAME_STATES:
        for to in FRAME_STATES:
            if (start, to) in FRAME_TRANSITIONS:
                continue
            rec.state = start
            with pytest.raises(IllegalMove, match=f"frame 7: no move from '{start}' to '{to}'"):
                m.move_frame(7, to)
            assert rec.state == start
    for start in CHUNK_STATES:
        for to in CHUNK_STATES:
            if (start, to) not in CHUNK_TRANSITIONS:
                with pytest.raises(IllegalMove, match=f"chunk 9: no move from '{start}' to '{to}'"):
                    m.move_chunk(Chunk(9, [7], state=start), to)


def test_only_the_machine_moves_a_state() -> None:
    """Only move_frame and move_chunk assign a state (the tests above set one by hand);
    the polling loop assigns none."""
    import re

    from motion.pipeline.farm import scheduler

    assert len(re.findall(r"\.state\s*=[^=]", Path(lifecycle.__file__).read_text())) == 2
    assert not re.findall(r"\.(state|status)\s*=[^=]", Path(scheduler.__file__).read_text())


def result(chunk_id: int, worker: str, ok: Sequence[int] = (), failed: Sequence[int] = (), held: dict[int, str] | None = None,
           done: Sequence[int] = (), disk: str | None = None) -> ChunkResult:
    res = ChunkResult(chunk_id=chunk_id, worker=worker, held_elsewhere=dict(held or {}), already_done=list(done), disk_fault=disk)
    res.results += [FrameResult(f, f"out/{f}.exr", True, worker, cold=k == 0, setup_s=0.5, render_s=0.25) for k, f in enumerate(ok)]
    res.results += [FrameResult(f, "", False, worker, error="boom") for f in failed]
    return res


def states(m: Lifecycle) -> dict[int, str]:
    return {f: r.state for f, r in m.frames.items()}


def test_events_in_decisions_out_through_a_retry_and_a_held_frame() -> None:
    m = Lifecycle(FarmConfig(retries=1, max_worker_failures=5))
    m.add([[0, 1, 2, 3]])
    [go] = m.assign(["a", "b"], ["a", "b"], now=0.0)  # one chunk: 'b' stays idle
    assert isinstance(go, Submit) and go.worker == "a" and go.chunk.frames == [0, 1, 2, 3]
    assert set(states(m).values()) == {"running"} and m.frames[0].attempts == 1
    out = m.finished("a", go.chunk.id, result(go.chunk.id, "a", ok=[0], failed=[1], held={2: "h:9"}, done=[3]))
    assert out == [Notify("rendered", {"frame": 0, "error": None}), Notify("skipped", {"frame": 3, "error": None}),
                   Notify("held", {"frame": 2, "holder": "h:9"}),
                   Notify("retry", {"frames": [1], "worker": "a", "error": "boom", "attempt": 1})]
    assert states(m) == {0: "rendered", 1: "queued", 2: "held", 3: "skipped"} and m.held == {2: "h:9"}
    assert m.workers["a"].first_frame_s == 0.75 and m.workers["a"].failures == 1
    assert m.assign(["a"], ["a", "b"], now=1.0) == []  # the retry waits for a worker it has not failed on
    [again] = m.assign(["b"], ["a", "b"], now=1.0)
    assert again.worker == "b" and again.chunk.frames == [1] and again.chunk.attempt == 1
    assert m.held_checked(finished=[], released=[2]) == [] and states(m)[2] == "queued"
    m.finished("b", again.chunk.id, result(again.chunk.id, "b", ok=[1]))
    [last] = m.assign(["a", "b"], ["a", "b"], now=2.0)
    assert last.worker == "a" and last.chunk.frames == [2]
    m.finished("a", last.chunk.id, result(last.chunk.id, "a", ok=[2]))
    assert not m.busy and {r.status for r in m.frames.values()} == {"rendered", "skipped"}
    assert m.frames[1].attempts == 2 and m.frames[1].errors == ["boom"]


def test_a_timed_out_chunk_stops_its_worker_cleans_up_and_fails_when_retries_are_spent() -> None:
    m = Lifecycle(FarmConfig(retries=0, task_timeout_s=30.0, max_worker_failures=1))
    m.add([[4, 5]])
    [go] = m.assign(["w"], ["w"], now=100.0)
    assert m.timed_out(now=130.0) == []  # not past 30 s yet
    why = "chunk 4-5 timed out after 30s on w"
    assert m.timed_out(now=130.5) == [StopWorker("w", "timeout"), Notify("excluded", {"worker": "w", "reason": why}), StopWorker("w", "excluded"),
                                      Cleanup((4, 5)), Notify("failed", {"frame": 4, "error": why}), Notify("failed", {"frame": 5, "error": why})]
    assert m.workers["w"].lost == [why] and m.excluded == {"w"} and not m.busy


def test_a_disk_fault_stops_queued_and_held_frames_at_once_and_blames_nobody() -> None:
    m = Lifecycle(FarmConfig(retries=3, max_worker_failures=1))
    m.add([[0, 1, 2], [3], [4]])
    [c0, c1] = m.assign(["a", "b"], ["a", "b"], now=0.0)
    m.finished("b", c1.chunk.id, result(c1.chunk.id, "b", held={3: "h:1"}))
    out = m.finished("a", c0.chunk.id, result(c0.chunk.id, "a", ok=[0], disk="no space left on device"))
    assert out == [Notify("rendered", {"frame": 0, "error": None}), Notify("disk_fault", {"worker": "a", "error": "no space left on device"})]
    assert states(m) == {0: "rendered", 1: "stopped", 2: "stopped", 3: "stopped", 4: "stopped"} and not m.busy
    assert m.frames[4].errors == ["not rendered: the job stopped on a disk fault (no space left on device)"]
    assert m.frames[4].status == "pending" and not m.excluded and m.workers["a"].failures == 0


def test_no_usable_worker_fails_the_queued_frames_after_the_grace() -> None:
    m = Lifecycle(FarmConfig(), no_worker_grace_s=5.0)
    m.add([[0], [1]])
    assert m.workers_seen([], can_grow=True, now=10.0) == []
    assert m.workers_seen([], can_grow=True, now=15.0) == []  # 5 s of grace, not past it
    out = m.workers_seen([], can_grow=True, now=15.5)
    assert out == [Notify("failed", {"frame": f, "error": "no usable workers left (none connected)"}) for f in (0, 1)]


def test_a_lost_worker_without_a_chunk_still_counts_a_failure() -> None:
    m = Lifecycle(FarmConfig(max_worker_failures=1))
    assert m.lost("gone", None, "left the cluster") == [Notify("excluded", {"worker": "gone", "reason": "left the cluster"}), StopWorker("gone", "excluded")]
    assert m.workers["gone"].lost == ["left the cluster"]


def test_an_interrupt_stops_every_unfinished_frame_and_settles_by_what_is_on_disk() -> None:
    m = Lifecycle(FarmConfig())
    m.add([[0, 1], [2], [3]])
    [c0, c1] = m.assign(["a", "b"], ["a", "b"], now=0.0)
    m.finished("b", c1.chunk.id, result(c1.chunk.id, "b", held={2: "h:1"}))
    assert m.interrupted() == [Cleanup((0, 1))]
    assert states(m) == {0: "stopped", 1: "stopped", 2: "stopped", 3: "stopped"} and not m.busy
    assert m.interrupted() == []  # idempotent
    assert m.settle_interrupted(on_disk={1}) == ([1], [0, 2, 3])
    assert states(m) == {0: "not_rendered", 1: "rendered", 2: "not_rendered", 3: "not_rendered"}
