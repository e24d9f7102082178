"""The farm's one scheduling loop, shared by both executors.

Chunks go to idle workers, one at a time each (so the scheduler always knows who runs
what and since when). A chunk whose worker dies, times out, or whose frames fail is
retried on another worker, up to `retries` more times; a worker with
`max_worker_failures` failures is excluded for the job; frames that fail on every attempt
are recorded with their last error, and the rest of the job still finishes. Frames another
render holds a claim on are watched and re-queued only if that render gives up on them.

A disk fault (the output disk full, read-only or refusing us) is no worker's fault and no
retry can mend it: the job stops taking chunks at once (`disk_fault` says why), running
chunks come back on their own, and nobody is excluded.
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Callable, Literal, get_args

from ..frame_output import is_complete
from ..bake import BakedFrame
from ..render.job import FrameResult, RenderJob, expected_meta
from .claims import claim_path, is_stale, read_claim, release, remove_partials
from .config import FarmConfig
from .executor import Done, Executor, FrameWritten, Lost
from .task import TaskContext


@dataclass
class Chunk:
    """A task: contiguous frames run together on one worker, its attempt count and the workers it failed on."""

    id: int
    frames: list[int]
    attempt: int = 0
    failed_on: set[str] = field(default_factory=set)


# A frame's state in one run is a closed set, and every allowed move between states is one
# entry below (as Dask's scheduler keeps its task states): a new state or move is one line here.
FrameState = Literal["pending", "rendered", "skipped", "done_elsewhere", "failed", "not_rendered"]
FRAME_STATES: tuple[FrameState, ...] = get_args(FrameState)

TRANSITIONS: dict[tuple[FrameState, FrameState], str] = {
    ("pending", "rendered"): "a worker wrote it (or finished writing it before an interrupt)",
    ("pending", "skipped"): "complete on disk, made from this scene and settings (resume)",
    ("pending", "done_elsewhere"): "another render holding its claim finished it",
    ("pending", "failed"): "every attempt failed, the disk refused it, or no usable worker was left",
    ("pending", "not_rendered"): "the job was interrupted before it was rendered",
}


@dataclass
class FrameRecord:
    """One frame's story for the report; its `status` moves only along `TRANSITIONS`."""

    frame: int
    status: FrameState = "pending"
    attempts: int = 0
    result: FrameResult | None = None
    errors: list[str] = field(default_factory=list)

    def move(self, to: FrameState) -> None:
        """Move to state `to`; a move the table does not allow is a scheduler bug and raises."""
        if (self.status, to) not in TRANSITIONS:
            raise RuntimeError(f"frame {self.frame}: no move from {self.status!r} to {to!r} (farm/scheduler.py TRANSITIONS)")
        self.status = to


@dataclass
class WorkerRecord:
    """What one worker did in this run: frames, chunks, failures, exclusion, cold and warm timings."""

    name: str
    frames: int = 0
    chunks: int = 0
    failures: int = 0
    excluded: bool = False
    first_frame_s: float | None = None  # setup + render of its cold (first) frame
    warm_render_s: list[float] = field(default_factory=list)
    lost: list[str] = field(default_factory=list)


Notify = Callable[[str, dict[str, Any]], None]


class Scheduler:
    """Drive an executor until every frame is rendered, complete elsewhere, or failed."""

    def __init__(
        self,
        executor: Executor,
        job: RenderJob,
        inputs: Mapping[int, BakedFrame],
        ctx: TaskContext,
        config: FarmConfig,
        notify: Notify | None = None,
        no_worker_grace_s: float = 120.0,
        poll_s: float = 0.2,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """`clock` gives the time in seconds for timeouts, claim checks and the no-worker
        grace (tests drive the decisions with a scripted executor and a clock of their own:
        tests/test_farm_scheduler.py)."""
        self.clock = clock
        self.ex = executor
        self.job = job
        self.inputs = inputs
        self.ctx = ctx
        self.cfg = config
        self.notify = notify or (lambda kind, data: None)
        self.grace_s = no_worker_grace_s
        self.poll_s = poll_s
        self.frames: dict[int, FrameRecord] = {}
        self.workers: dict[str, WorkerRecord] = {}
        self.pending: deque[Chunk] = deque()
        self.running: dict[str, tuple[Chunk, float]] = {}
        self.waiting: dict[int, str] = {}  # frame -> holder (another render)
        self.failures: Counter[str] = Counter()
        self.excluded: set[str] = set()
        self._next_id = 0
        self._no_worker_since: float | None = None
        self._last_wait_check = 0.0
        self.disk_fault: str | None = None  # set when the disk refused a write: the job stops

    # --- bookkeeping ------------------------------------------------------------------
    def _worker(self, name: str) -> WorkerRecord:
        if name not in self.workers:
            self.workers[name] = WorkerRecord(name)
        return self.workers[name]

    def _chunk(self, frames: list[int], attempt: int = 0, failed_on: set[str] | None = None) -> Chunk:
        c = Chunk(self._next_id, list(frames), attempt, set(failed_on or ()))
        self._next_id += 1
        return c

    def _final(self, frame: int, status: FrameState, error: str | None = None) -> None:
        rec = self.frames[frame]
        rec.move(status)
        if error:
            rec.errors.append(error)
        self.notify(status, {"frame": frame, "error": error})

    def _retry_or_fail(self, chunk: Chunk, frames: list[int], worker: str, error: str) -> None:
        for f in frames:
            self.frames[f].errors.append(error)
        if chunk.attempt < self.cfg.retries:
            self.pending.append(self._chunk(frames, chunk.attempt + 1, chunk.failed_on | {worker}))
            self.notify("retry", {"frames": frames, "worker": worker, "error": error, "attempt": chunk.attempt + 1})
        else:
            for f in frames:
                self.frames[f].move("failed")
                self.notify("failed", {"frame": f, "error": error})

    def _worker_failed(self, worker: str, reason: str) -> None:
        self.failures[worker] += 1
        rec = self._worker(worker)
        rec.failures += 1
        if self.failures[worker] >= self.cfg.max_worker_failures and worker not in self.excluded:
            self.excluded.add(worker)
            rec.excluded = True
            self.notify("excluded", {"worker": worker, "reason": reason})
            self.ex.stop_worker(worker, "excluded")

    # --- the loop ---------------------------------------------------------------------
    def run(self, chunks: list[list[int]]) -> None:
        """Run every chunk to the end: submit to idle workers, collect results, retry failures
        elsewhere, exclude failing workers, time out stuck chunks, wait on frames another job holds."""
        for frames in chunks:
            for f in frames:
                self.frames[f] = FrameRecord(f)
            self.pending.append(self._chunk(frames))
        while self.pending or self.running or self.waiting:
            if self.disk_fault is not None:
                self._stop_for_disk_fault()
                if not self.running:
                    break
            self._assign()
            for event in self.ex.poll(self.poll_s):
                if isinstance(event, Done):
                    self._done(event)
                elif isinstance(event, FrameWritten):
                    self.notify("written", {"frame": event.frame, "worker": event.worker, "seconds": event.seconds, "path": self.ctx.paths.get(event.frame)})
                else:
                    self._lost(event)
            self._check_timeouts()
            self._check_waiting()
            self._check_workers()

    def _assign(self) -> None:
        if self.disk_fault is not None:
            return
        usable = [w for w in self.ex.live_workers() if w not in self.excluded]
        for w in self.ex.idle_workers():
            if w in self.excluded or w in self.running or not self.pending:
                continue
            pick = None
            for c in self.pending:
                if w not in c.failed_on:
                    pick = c
                    break
            if pick is None:
                # every pending chunk already failed here: wait for a worker it has not
                # failed on, unless there is none
                c = self.pending[0]
                if any(u not in c.failed_on for u in usable):
                    continue
                pick = c
            self.pending.remove(pick)
            for f in pick.frames:
                self.frames[f].attempts += 1
            self.running[w] = (pick, self.clock())
            self.ex.submit(w, pick.id, self.job, [self.inputs[f] for f in pick.frames], self.ctx.only(pick.frames))

    def _take_running(self, worker: str, chunk_id: int | None) -> Chunk | None:
        entry = self.running.get(worker)
        if entry is None or (chunk_id is not None and entry[0].id != chunk_id):
            return None
        del self.running[worker]
        return entry[0]

    def _stop_for_disk_fault(self) -> None:
        """Drop every queued chunk and watched frame: they stay 'pending' with the reason."""
        why = f"not rendered: the job stopped on a disk fault ({self.disk_fault})"
        while self.pending:
            for f in self.pending.popleft().frames:
                if self.frames[f].status == "pending":
                    self.frames[f].errors.append(why)
        for f in list(self.waiting):
            del self.waiting[f]
            self.frames[f].errors.append(why)

    def _disk_fault_done(self, ev: Done, chunk: Chunk) -> None:
        """A chunk that hit a disk fault: keep what it finished, blame no worker, retry
        nothing, and stop the job."""
        res = ev.result
        wrec = self._worker(ev.worker)
        wrec.chunks += 1
        reported = set()
        for r in res.results:
            reported.add(r.frame)
            rec = self.frames[r.frame]
            rec.result = r
            if r.ok:
                wrec.frames += 1
                self._final(r.frame, "rendered")
            else:
                self._final(r.frame, "failed", r.error or "disk fault")
        for f in res.already_done:
            reported.add(f)
            self._final(f, "skipped")
        if self.disk_fault is None:
            self.disk_fault = res.disk_fault or next((r.error for r in res.results if getattr(r, "disk_fault", False)), "disk fault")
            self.notify("disk_fault", {"worker": ev.worker, "error": self.disk_fault})
        for f in chunk.frames:
            if f not in reported and f not in res.held_elsewhere:
                self.frames[f].errors.append(f"not rendered: the job stopped on a disk fault ({self.disk_fault})")

    def _done(self, ev: Done) -> None:
        chunk = self._take_running(ev.worker, ev.chunk_id)
        if chunk is None:
            return
        res = ev.result
        if getattr(res, "disk_fault", None) or any(getattr(r, "disk_fault", False) for r in res.results):
            self._disk_fault_done(ev, chunk)
            return
        wrec = self._worker(ev.worker)
        wrec.chunks += 1
        failed: list[int] = []
        last_error = ""
        for r in res.results:
            rec = self.frames[r.frame]
            rec.result = r
            if r.ok:
                wrec.frames += 1
                if r.cold and wrec.first_frame_s is None:
                    wrec.first_frame_s = r.setup_s + r.render_s
                elif not r.cold:
                    wrec.warm_render_s.append(r.render_s)
                self._final(r.frame, "rendered")
            else:
                failed.append(r.frame)
                last_error = r.error or "failed"
        for f in res.already_done:
            self._final(f, "skipped")
        for f, holder in res.held_elsewhere.items():
            self.waiting[f] = holder
            self.notify("held", {"frame": f, "holder": holder})
        if failed:
            self._worker_failed(ev.worker, last_error)
            self._retry_or_fail(chunk, failed, ev.worker, last_error)

    def _lost(self, ev: Lost) -> None:
        self._worker(ev.worker).lost.append(ev.reason)
        chunk = self._take_running(ev.worker, ev.chunk_id) if ev.chunk_id is not None else self.running.pop(ev.worker, (None, 0))[0]
        self._worker_failed(ev.worker, ev.reason)
        if chunk is not None:
            self._cleanup(chunk.frames)
            self._retry_or_fail(chunk, chunk.frames, ev.worker, ev.reason)

    def _cleanup(self, frames: list[int]) -> None:
        """After a worker vanished mid-chunk: its partial files and our claims go."""
        for f in frames:
            path = self.ctx.paths[f]
            remove_partials(path)
            release(path, self.ctx.run_id)

    def _check_timeouts(self) -> None:
        now = self.clock()
        for w, (chunk, t0) in list(self.running.items()):
            if now - t0 > self.cfg.task_timeout_s:
                from ..timeline import format_range

                reason = f"chunk {format_range(chunk.frames[0], chunk.frames[-1])} timed out after {self.cfg.task_timeout_s:g}s on {w}"
                del self.running[w]
                self.ex.stop_worker(w, "timeout")
                self._worker(w).lost.append(reason)
                self._worker_failed(w, reason)
                self._cleanup(chunk.frames)
                self._retry_or_fail(chunk, chunk.frames, w, reason)

    def _check_waiting(self, every_s: float = 1.0) -> None:
        now = self.clock()
        if not self.waiting or now - self._last_wait_check < every_s:
            return
        self._last_wait_check = now
        requeue: list[int] = []
        for f in sorted(self.waiting):
            path = self.ctx.paths[f]
            if self.ctx.resume and is_complete(path, expected_meta(self.job, self.inputs[f])):
                del self.waiting[f]
                self._final(f, "done_elsewhere")
                continue
            cp = claim_path(path)
            info = read_claim(cp)
            if info is None or is_stale(cp, info, self.cfg.stale_after_s):
                del self.waiting[f]
                requeue.append(f)
        if requeue:
            self.pending.append(self._chunk(requeue))

    def _check_workers(self) -> None:
        if not self.pending:
            self._no_worker_since = None
            return
        usable = [w for w in self.ex.live_workers() if w not in self.excluded]
        if usable:
            self._no_worker_since = None
            return
        now = self.clock()
        if self._no_worker_since is None:
            self._no_worker_since = now
        if not self.ex.can_grow() or now - self._no_worker_since > self.grace_s:
            why = "no usable workers left (" + (f"{len(self.excluded)} excluded after repeated failures" if self.excluded else "none connected") + ")"
            while self.pending:
                c = self.pending.popleft()
                for f in c.frames:
                    rec = self.frames[f]
                    last = f"; last error: {rec.errors[-1]}" if rec.errors else ""
                    self._final(f, "failed", why + last)

    def settle_interrupted(self) -> tuple[list[int], list[int]]:
        """After an interrupt: frames still pending whose file a worker finished before
        the stop are `rendered` (complete on disk, made from this job); the others are
        `not_rendered`, never `failed` (nothing went wrong with them). Returns both lists."""
        written, not_rendered = [], []
        for f, rec in sorted(self.frames.items()):
            if rec.status != "pending":
                continue
            if is_complete(self.ctx.paths[f], expected_meta(self.job, self.inputs[f])):
                rec.move("rendered")
                written.append(f)
            else:
                rec.move("not_rendered")
                not_rendered.append(f)
        return written, not_rendered

    def abandon(self) -> list[int]:
        """On interrupt: the frames that were running; their partial files and our claims
        are removed (the executor has already stopped the workers)."""
        frames = [f for chunk, _ in self.running.values() for f in chunk.frames]
        self._cleanup(frames)
        self.running.clear()
        return frames
