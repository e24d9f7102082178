"""The farm's one polling loop, shared by every executor.

It asks the executor what happened and feeds each event into the frame and chunk state
machine (`lifecycle.Lifecycle`: retries elsewhere, exclusion, timeouts, disk faults,
workers running out, interrupts), then acts on the decisions the machine returns: submit a
chunk, stop a worker, clean up a vanished worker's partial files and claims, tell the
progress display. The loop does the I/O the machine needs (the executor, the clock, claims
and frames on disk); the machine decides.

Chunks go to idle workers, one at a time each (so the loop always knows who runs what and
since when). Frames another render holds a claim on are looked at on disk every second:
counted done when that render finished them, queued again when it gave them up.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, Callable

from ..bake import BakedFrame
from ..identity import complete_as
from ..render.worker.job import RenderJob
from .claims import claim_path, is_stale, read_claim, release, remove_partials
from .config import FarmConfig
from .executor import Done, Executor, FrameWritten, Lost
from .lifecycle import Cleanup, Decision, FrameRecord, Lifecycle, Notify, StopWorker, Submit, WorkerRecord
from .task import TaskContext

Listener = Callable[[str, dict[str, Any]], None]


class Scheduler:
    """Drive an executor until every frame is rendered, complete elsewhere, or failed."""

    def __init__(
        self,
        executor: Executor,
        job: RenderJob,
        inputs: Mapping[int, BakedFrame],
        ctx: TaskContext,
        config: FarmConfig,
        notify: Listener | None = None,
        no_worker_grace_s: float = 120.0,
        poll_s: float = 0.2,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """`clock` gives the time in seconds for timeouts, claim checks and the no-worker
        grace (tests drive the decisions with a scripted executor and a clock of their own:
        tests/farm/test_scheduler.py)."""
        self.clock = clock
        self.ex = executor
        self.job = job
        self.inputs = inputs
        self.ctx = ctx
        self.cfg = config
        self.notify = notify or (lambda kind, data: None)
        self.poll_s = poll_s
        self.machine = Lifecycle(config, no_worker_grace_s)
        self._last_held_check = 0.0

    @property
    def frames(self) -> dict[int, FrameRecord]:
        """Each frame's record (state, attempts, result, errors), by frame."""
        return self.machine.frames

    @property
    def workers(self) -> dict[str, WorkerRecord]:
        """Each worker's record, by name."""
        return self.machine.workers

    @property
    def excluded(self) -> set[str]:
        """The workers excluded for this job after repeated failures."""
        return self.machine.excluded

    @property
    def disk_fault(self) -> str | None:
        """Why the job stopped on a disk fault, or None."""
        return self.machine.disk_fault

    # --- the loop ---------------------------------------------------------------------
    def run(self, chunks: list[list[int]]) -> None:
        """Run every chunk to the end: submit to idle workers, collect results, retry failures
        elsewhere, exclude failing workers, time out stuck chunks, wait on frames another job holds."""
        m = self.machine
        m.add(chunks)
        while m.busy:
            self._act(m.assign(self.ex.idle_workers(), self.ex.live_workers(), self.clock()))
            for event in self.ex.poll(self.poll_s):
                if isinstance(event, Done):
                    self._act(m.finished(event.worker, event.chunk_id, event.result))
                elif isinstance(event, FrameWritten):
                    self.notify("written", {"frame": event.frame, "worker": event.worker, "seconds": event.seconds, "path": self.ctx.paths.get(event.frame)})
                elif isinstance(event, Lost):
                    self._act(m.lost(event.worker, event.chunk_id, event.reason))
            self._act(m.timed_out(self.clock()))
            self._check_held()
            self._act(m.workers_seen(self.ex.live_workers(), self.ex.can_grow(), self.clock()))

    def _act(self, decisions: list[Decision]) -> None:
        """Carry out the machine's decisions, in order."""
        for d in decisions:
            if isinstance(d, Submit):
                frames = d.chunk.frames
                self.ex.submit(d.worker, d.chunk.id, self.job, [self.inputs[f] for f in frames], self.ctx.only(frames))
            elif isinstance(d, StopWorker):
                self.ex.stop_worker(d.worker, d.reason)
            elif isinstance(d, Cleanup):
                self._cleanup(d.frames)
            elif isinstance(d, Notify):
                self.notify(d.kind, d.data)

    def _cleanup(self, frames: tuple[int, ...]) -> None:
        """After a worker vanished mid-chunk: its partial files and our claims go."""
        for f in frames:
            path = self.ctx.paths[f]
            remove_partials(path)
            release(path, self.ctx.run_id)

    def _check_held(self, every_s: float = 1.0) -> None:
        """Look at the frames another render holds, at most every `every_s` seconds."""
        now = self.clock()
        if not self.machine.held or now - self._last_held_check < every_s:
            return
        self._last_held_check = now
        finished, released = [], []
        for f in sorted(self.machine.held):
            path = self.ctx.paths[f]
            if self.ctx.resume and complete_as(path, self.job.identity(self.inputs[f])):
                finished.append(f)
                continue
            cp = claim_path(path)
            info = read_claim(cp)
            if info is None or is_stale(cp, info, self.cfg.stale_after_s):
                released.append(f)
        self._act(self.machine.held_checked(finished, released))

    def abandon(self) -> list[int]:
        """On interrupt: the frames that were running; their partial files and our claims
        are removed (the executor has already stopped the workers)."""
        frames = [f for chunk in self.machine.running.values() for f in chunk.frames]
        self._act(self.machine.interrupted())
        return frames

    def settle_interrupted(self) -> tuple[list[int], list[int]]:
        """After an interrupt: unfinished frames whose file a worker finished before the
        stop are `rendered` (complete on disk, made from this job); the others are
        `not_rendered`, never `failed` (nothing went wrong with them). Returns both lists."""
        self._act(self.machine.interrupted())
        on_disk = {f for f in self.machine.stopped() if complete_as(self.ctx.paths[f], self.job.identity(self.inputs[f]))}
        return self.machine.settle_interrupted(on_disk)
