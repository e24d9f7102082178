"""The farm's frame and chunk lifecycle: one state machine, apart from any I/O.

A frame and a chunk (contiguous frames run together on one worker) each have a closed set
of states, and every allowed move between two states is one entry of a transitions table
that names the move's handler, as Dask's scheduler keeps its task states. A move the table
does not list is a scheduler bug and raises `IllegalMove`.

The machine does no I/O: the polling loop (`scheduler.py`) feeds it events (workers idle,
a chunk finished, a worker lost, a chunk past its timeout, frames another render held
checked on disk, workers seen, an interrupt) and acts on the decisions each event returns
(`Submit`, `StopWorker`, `Cleanup`, `Notify`), in order. Its rules:

- a chunk goes to an idle worker it has not failed on (to one it failed on only when no
  usable worker is left that it has not failed on);
- a chunk whose worker dies, times out, or whose frames fail is retried as a new chunk of
  the failed frames, up to `retries` more times; then its frames fail with the last error;
- a worker with `max_worker_failures` failures is excluded for the job and stopped;
- a disk fault (the output disk full, read-only or refusing us) is no worker's fault: the
  job stops taking chunks at once, queued and held frames stop with the reason, running
  chunks come back on their own, nobody is excluded and nothing is retried;
- with no usable worker and none that can appear within the grace, queued frames fail;
- an interrupt stops every unfinished frame; the loop then says which of them are complete
  on disk (`rendered`) and the rest are `not_rendered`, never `failed`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Callable, Union

from ..render.worker.job import FrameResult
from ..timeline import format_range
from .config import FarmConfig
from .states import CHUNK_STATES, FINAL_CHUNK_STATES, FINAL_FRAME_STATES, FRAME_STATES, ChunkState, FrameState
from .task import ChunkResult


class IllegalMove(RuntimeError):
    """A move the transitions table does not list: a bug in the scheduler, never bad input."""


@dataclass
class FrameRecord:
    """One frame's story for the report: its state, attempts, last result and errors."""

    frame: int
    state: FrameState = "queued"
    attempts: int = 0
    result: FrameResult | None = None
    errors: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        """The report's word for the frame: its final state, or 'pending' while unfinished
        (a frame the job stopped before it ran stays 'pending' with the reason)."""
        return self.state if self.state in FINAL_FRAME_STATES else "pending"


@dataclass
class Chunk:
    """A task: contiguous frames run together on one worker, its attempt count, the workers
    it failed on, its state, and (once moved) where it ran, since when, and what came back."""

    id: int
    frames: list[int]
    attempt: int = 0
    failed_on: set[str] = field(default_factory=set)
    state: ChunkState = "queued"
    worker: str = ""
    started: float = 0.0
    result: ChunkResult | None = None  # what a finished chunk brought back
    reason: str | None = None  # why it was lost, stopped or failed


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


@dataclass(frozen=True)
class Submit:
    """Start `chunk` on the idle `worker`."""

    worker: str
    chunk: Chunk


@dataclass(frozen=True)
class StopWorker:
    """Stop `worker` (it timed out, or it is excluded)."""

    worker: str
    reason: str


@dataclass(frozen=True)
class Cleanup:
    """A worker vanished mid-chunk: remove these frames' partial files and our claims."""

    frames: tuple[int, ...]


@dataclass(frozen=True)
class Notify:
    """Tell the progress display (and any listener) what happened: `kind` and its data."""

    kind: str
    data: dict[str, Any]


Decision = Union[Submit, StopWorker, Cleanup, Notify]


class Lifecycle:
    """The frames and chunks of one run, moved only along FRAME_TRANSITIONS and
    CHUNK_TRANSITIONS. Each event method returns the decisions the loop must act on."""

    def __init__(self, config: FarmConfig, no_worker_grace_s: float = 120.0) -> None:
        """`config`: retries, timeout and exclusion limits; `no_worker_grace_s`: how long
        queued frames wait for a usable worker to appear before they fail."""
        self.cfg = config
        self.grace_s = no_worker_grace_s
        self.frames: dict[int, FrameRecord] = {}
        self.workers: dict[str, WorkerRecord] = {}
        self.excluded: set[str] = set()
        self.queue: deque[Chunk] = deque()  # chunks in state 'queued', in order
        self.running: dict[str, Chunk] = {}  # worker -> its chunk in state 'running'
        self.held: dict[int, str] = {}  # frame in state 'held' -> the render holding its claim
        self.disk_fault: str | None = None  # set when the disk refused a write: the job stops
        self._next_id = 0
        self._no_worker_since: float | None = None
        self._out: list[Decision] = []

    # --- moves ------------------------------------------------------------------------
    def move_frame(self, frame: int, to: FrameState, why: str | None = None) -> None:
        """Move `frame` to `to` through its table entry's handler (`why`: an error or a
        holder, as the handler takes it); a move the table does not list raises."""
        rec = self.frames[frame]
        handler = FRAME_TRANSITIONS.get((rec.state, to))
        if handler is None:
            raise IllegalMove(f"frame {frame}: no move from {rec.state!r} to {to!r} (farm/lifecycle.py FRAME_TRANSITIONS)")
        if rec.state == "held":
            del self.held[frame]
        rec.state = to
        handler(self, rec, why)

    def move_chunk(self, chunk: Chunk, to: ChunkState) -> None:
        """Move `chunk` to `to` through its table entry's handler; a move the table does
        not list raises. Only queued and running chunks are kept (`queue`, `running`)."""
        handler = CHUNK_TRANSITIONS.get((chunk.state, to))
        if handler is None:
            raise IllegalMove(f"chunk {chunk.id}: no move from {chunk.state!r} to {to!r} (farm/lifecycle.py CHUNK_TRANSITIONS)")
        if chunk.state == "queued":
            self.queue.remove(chunk)
        elif chunk.state == "running":
            del self.running[chunk.worker]
        chunk.state = to
        if to == "running":
            self.running[chunk.worker] = chunk
        handler(self, chunk)

    # --- frame handlers ---------------------------------------------------------------
    def _count_attempt(self, rec: FrameRecord, why: str | None) -> None:
        rec.attempts += 1

    def _keep_why(self, rec: FrameRecord, why: str | None) -> None:
        if why:
            rec.errors.append(why)

    def _settle(self, rec: FrameRecord, why: str | None) -> None:
        self._keep_why(rec, why)
        self._out.append(Notify(rec.state, {"frame": rec.frame, "error": why}))

    def _hold(self, rec: FrameRecord, holder: str | None) -> None:
        self.held[rec.frame] = holder or "?"
        self._out.append(Notify("held", {"frame": rec.frame, "holder": holder}))

    # --- chunk handlers ---------------------------------------------------------------
    def _chunk_submitted(self, chunk: Chunk) -> None:
        for f in chunk.frames:
            self.move_frame(f, "running")
        self._out.append(Submit(chunk.worker, chunk))

    def _chunk_stopped(self, chunk: Chunk) -> None:
        for f in chunk.frames:
            self.move_frame(f, "stopped", chunk.reason)

    def _chunk_abandoned(self, chunk: Chunk) -> None:
        self._out.append(Cleanup(tuple(chunk.frames)))
        self._chunk_stopped(chunk)

    def _chunk_failed(self, chunk: Chunk) -> None:
        for f in chunk.frames:
            errors = self.frames[f].errors
            last = f"; last error: {errors[-1]}" if errors else ""
            self.move_frame(f, "failed", f"{chunk.reason}{last}")

    def _chunk_lost(self, chunk: Chunk) -> None:
        reason = chunk.reason or "lost"
        self._worker_failed(chunk.worker, reason)
        self._out.append(Cleanup(tuple(chunk.frames)))
        self._retry_or_fail(chunk, chunk.frames, reason)

    def _chunk_done(self, chunk: Chunk) -> None:
        res = chunk.result
        if res is None:
            raise IllegalMove(f"chunk {chunk.id}: done without a result")
        self._worker(chunk.worker).chunks += 1
        if res.disk_fault or any(getattr(r, "disk_fault", False) for r in res.results):
            self._done_on_disk_fault(chunk, res)
            return
        failed: list[int] = []
        last_error = ""
        for r in res.results:
            self.frames[r.frame].result = r
            if r.ok:
                self._count_frame(chunk.worker, r)
                self.move_frame(r.frame, "rendered")
            else:
                failed.append(r.frame)
                last_error = r.error or "failed"
        for f in res.already_done:
            self.move_frame(f, "skipped")
        for f, holder in res.held_elsewhere.items():
            self.move_frame(f, "held", holder)
        if failed:
            self._worker_failed(chunk.worker, last_error)
            self._retry_or_fail(chunk, failed, last_error)

    def _done_on_disk_fault(self, chunk: Chunk, res: ChunkResult) -> None:
        """A chunk that hit a disk fault: keep what it finished, blame no worker, retry
        nothing, stop the job; its frames it never reached stop with the reason."""
        reported: set[int] = set()
        wrec = self._worker(chunk.worker)
        for r in res.results:
            reported.add(r.frame)
            self.frames[r.frame].result = r
            if r.ok:
                wrec.frames += 1
                self.move_frame(r.frame, "rendered")
            else:
                self.move_frame(r.frame, "failed", r.error or "disk fault")
        for f in res.already_done:
            reported.add(f)
            self.move_frame(f, "skipped")
        if self.disk_fault is None:
            self.disk_fault = res.disk_fault or next((r.error for r in res.results if getattr(r, "disk_fault", False)), None) or "disk fault"
            self._out.append(Notify("disk_fault", {"worker": chunk.worker, "error": self.disk_fault}))
        for f in chunk.frames:
            if f not in reported:
                self.move_frame(f, "stopped", None if f in res.held_elsewhere else self._stopped_why())

    # --- shared steps -----------------------------------------------------------------
    def _worker(self, name: str) -> WorkerRecord:
        if name not in self.workers:
            self.workers[name] = WorkerRecord(name)
        return self.workers[name]

    def _count_frame(self, worker: str, r: FrameResult) -> None:
        wrec = self._worker(worker)
        wrec.frames += 1
        if r.cold and wrec.first_frame_s is None:
            wrec.first_frame_s = r.setup_s + r.render_s
        elif not r.cold:
            wrec.warm_render_s.append(r.render_s)

    def _queue(self, frames: Sequence[int], attempt: int = 0, failed_on: Iterable[str] = ()) -> None:
        self.queue.append(Chunk(self._next_id, list(frames), attempt, set(failed_on)))
        self._next_id += 1

    def _retry_or_fail(self, chunk: Chunk, frames: list[int], error: str) -> None:
        if chunk.attempt < self.cfg.retries:
            for f in frames:
                self.move_frame(f, "queued", error)
            self._queue(frames, chunk.attempt + 1, chunk.failed_on | {chunk.worker})
            self._out.append(Notify("retry", {"frames": frames, "worker": chunk.worker, "error": error, "attempt": chunk.attempt + 1}))
        else:
            for f in frames:
                self.move_frame(f, "failed", error)

    def _worker_failed(self, worker: str, reason: str) -> None:
        rec = self._worker(worker)
        rec.failures += 1
        if rec.failures >= self.cfg.max_worker_failures and worker not in self.excluded:
            self.excluded.add(worker)
            rec.excluded = True
            self._out.append(Notify("excluded", {"worker": worker, "reason": reason}))
            self._out.append(StopWorker(worker, "excluded"))

    def _stopped_why(self) -> str:
        return f"not rendered: the job stopped on a disk fault ({self.disk_fault})"

    def _decisions(self) -> list[Decision]:
        """End of an event: after a disk fault nothing stays queued or held (they stop
        with the reason); hand over the decisions."""
        if self.disk_fault is not None:
            while self.queue:
                chunk = self.queue[0]
                chunk.reason = self._stopped_why()
                self.move_chunk(chunk, "stopped")
            for f in sorted(self.held):
                self.move_frame(f, "stopped", self._stopped_why())
        out, self._out = self._out, []
        return out

    # --- events -----------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        """Whether any chunk is queued or running, or any frame held by another render."""
        return bool(self.queue or self.running or self.held)

    def add(self, chunks: Iterable[Sequence[int]]) -> None:
        """The job's chunks, queued in order; their frames start 'queued'."""
        for frames in chunks:
            for f in frames:
                self.frames[f] = FrameRecord(f)
            self._queue(frames)

    def assign(self, idle: Sequence[str], live: Sequence[str], now: float) -> list[Decision]:
        """Workers are idle (`live`: every worker alive): queued chunks go to them."""
        usable = [w for w in live if w not in self.excluded]
        for w in idle:
            if w in self.excluded or w in self.running or not self.queue:
                continue
            pick = next((c for c in self.queue if w not in c.failed_on), None)
            if pick is None:
                # every queued chunk already failed here: wait for a worker it has not
                # failed on, unless there is none
                pick = self.queue[0]
                if any(u not in pick.failed_on for u in usable):
                    continue
            pick.worker, pick.started = w, now
            self.move_chunk(pick, "running")
        return self._decisions()

    def _take_running(self, worker: str, chunk_id: int | None) -> Chunk | None:
        chunk = self.running.get(worker)
        if chunk is None or (chunk_id is not None and chunk.id != chunk_id):
            return None
        return chunk

    def finished(self, worker: str, chunk_id: int, result: ChunkResult) -> list[Decision]:
        """A chunk came back (its frames may still have failed one by one)."""
        chunk = self._take_running(worker, chunk_id)
        if chunk is not None:
            chunk.result = result
            self.move_chunk(chunk, "done")
        return self._decisions()

    def lost(self, worker: str, chunk_id: int | None, reason: str) -> list[Decision]:
        """A worker went away or its task raised; `chunk_id` None: whatever it ran."""
        self._worker(worker).lost.append(reason)
        chunk = self._take_running(worker, chunk_id)
        if chunk is None:
            self._worker_failed(worker, reason)
        else:
            chunk.reason = reason
            self.move_chunk(chunk, "lost")
        return self._decisions()

    def timed_out(self, now: float) -> list[Decision]:
        """The clock moved: chunks running past the task timeout are cancelled (their
        worker stopped) and count as lost."""
        for w, chunk in list(self.running.items()):
            if now - chunk.started > self.cfg.task_timeout_s:
                reason = f"chunk {format_range(chunk.frames[0], chunk.frames[-1])} timed out after {self.cfg.task_timeout_s:g}s on {w}"
                self._out.append(StopWorker(w, "timeout"))
                self._worker(w).lost.append(reason)
                chunk.reason = reason
                self.move_chunk(chunk, "lost")
        return self._decisions()

    def held_checked(self, finished: Iterable[int], released: Iterable[int]) -> list[Decision]:
        """Frames another render held, looked at on disk: `finished` it completed them,
        `released` its claim is gone or stale (they are queued again, as one chunk)."""
        for f in finished:
            self.move_frame(f, "done_elsewhere")
        requeue = list(released)
        for f in requeue:
            self.move_frame(f, "queued")
        if requeue:
            self._queue(requeue)
        return self._decisions()

    def workers_seen(self, live: Sequence[str], can_grow: bool, now: float) -> list[Decision]:
        """The workers alive now: with chunks queued, no usable worker, and none that can
        appear (or the grace is over), the queued chunks fail, saying why."""
        if not self.queue or any(w not in self.excluded for w in live):
            self._no_worker_since = None
            return self._decisions()
        if self._no_worker_since is None:
            self._no_worker_since = now
        if not can_grow or now - self._no_worker_since > self.grace_s:
            why = "no usable workers left (" + (f"{len(self.excluded)} excluded after repeated failures" if self.excluded else "none connected") + ")"
            while self.queue:
                chunk = self.queue[0]
                chunk.reason = why
                self.move_chunk(chunk, "failed")
        return self._decisions()

    def interrupted(self) -> list[Decision]:
        """Ctrl-C or SIGTERM: running chunks are abandoned (their partial files and claims
        cleaned up), queued ones dropped, and every unfinished frame stops. Idempotent."""
        for chunk in list(self.running.values()):
            self.move_chunk(chunk, "stopped")
        while self.queue:
            self.move_chunk(self.queue[0], "stopped")
        for rec in self.frames.values():
            if rec.state in ("queued", "running", "held"):
                self.move_frame(rec.frame, "stopped")
        out, self._out = self._out, []
        return out

    def stopped(self) -> list[int]:
        """The frames in state 'stopped', in frame order."""
        return sorted(f for f, rec in self.frames.items() if rec.state == "stopped")

    def settle_interrupted(self, on_disk: Collection[int]) -> tuple[list[int], list[int]]:
        """After `interrupted`: each stopped frame is `rendered` if a worker finished its
        file before the stop (`on_disk`: the loop looked), else `not_rendered`. Returns both lists."""
        written, not_rendered = [], []
        for f in self.stopped():
            if f in on_disk:
                self.move_frame(f, "rendered")
                written.append(f)
            else:
                self.move_frame(f, "not_rendered")
                not_rendered.append(f)
        return written, not_rendered


FrameHandler = Callable[[Lifecycle, FrameRecord, Union[str, None]], None]
ChunkHandler = Callable[[Lifecycle, Chunk], None]

# Every allowed move of a frame, and its handler. A new state or move is one line here.
FRAME_TRANSITIONS: dict[tuple[FrameState, FrameState], FrameHandler] = {
    ("queued", "running"): Lifecycle._count_attempt,  # its chunk went to a worker
    ("queued", "failed"): Lifecycle._settle,  # no usable worker left
    ("queued", "stopped"): Lifecycle._keep_why,  # a disk fault or an interrupt before it ran
    ("running", "rendered"): Lifecycle._settle,  # a worker wrote it
    ("running", "skipped"): Lifecycle._settle,  # complete on disk, made from this scene and settings (resume)
    ("running", "held"): Lifecycle._hold,  # another render holds its claim: watched
    ("running", "queued"): Lifecycle._keep_why,  # its attempt failed: retried in a new chunk
    ("running", "failed"): Lifecycle._settle,  # every attempt failed, or the disk refused it
    ("running", "stopped"): Lifecycle._keep_why,  # its chunk stopped on a disk fault, or an interrupt
    ("held", "done_elsewhere"): Lifecycle._settle,  # the render holding its claim finished it
    ("held", "queued"): Lifecycle._keep_why,  # that render gave it up (claim gone or stale)
    ("held", "stopped"): Lifecycle._keep_why,  # a disk fault or an interrupt while watched
    ("stopped", "rendered"): Lifecycle._keep_why,  # after an interrupt: its file is complete on disk
    ("stopped", "not_rendered"): Lifecycle._keep_why,  # after an interrupt: it was not rendered
}

# Every allowed move of a chunk, and its handler.
CHUNK_TRANSITIONS: dict[tuple[ChunkState, ChunkState], ChunkHandler] = {
    ("queued", "running"): Lifecycle._chunk_submitted,  # an idle worker took it
    ("queued", "stopped"): Lifecycle._chunk_stopped,  # a disk fault or an interrupt before it ran
    ("queued", "failed"): Lifecycle._chunk_failed,  # no usable worker left
    ("running", "done"): Lifecycle._chunk_done,  # it came back: frames settle, failures retry
    ("running", "lost"): Lifecycle._chunk_lost,  # its worker died, its task raised, or it timed out
    ("running", "stopped"): Lifecycle._chunk_abandoned,  # an interrupt: its partial files and claims go
}
