"""The inline executor: a small job's chunks rendered in this process, one after another.

A CI smoke render is three 64x36 frames: spawning a worker per core costs each worker the
whole import of the stack and a cold scene build, far more than the frames (docs/farm.md
gives the figure). When the plan's estimate says the frames cost less than a worker's
start would save (`shot/render.py: choose_executor`), the farm runs them here through
the same scheduler: the same claims, resume checks, retries, per-frame progress and report,
and the same pixels (tests/cli/farm/test_ci.py renders the same frames inline, on 1 and on 2
workers and compares them bit for bit).

What it cannot do, and why that is fine for a small job: a chunk cannot be timed out or
killed (it runs on this thread; Ctrl-C still stops it between and inside frames), and a
crash of the renderer ends this process with it.
"""

from __future__ import annotations

import os
import socket
from typing import Sequence

from ..bake import BakedFrame
from ..render.worker.job import RenderJob
from .executor import Done, Event, FrameWritten, Lost
from .task import TaskContext, run_chunk


class InlineExecutor:
    """One worker, this process: `poll` runs the submitted chunk to its end."""

    kind = "inline"

    def __init__(self) -> None:
        self.name = f"{socket.gethostname()}:{os.getpid()}"
        self.n = 1
        self._chunk: tuple[int, RenderJob, list[BakedFrame], TaskContext] | None = None
        self._stopped = False

    def idle_workers(self) -> list[str]:
        """This process, when it is not running a chunk."""
        return [] if self._stopped or self._chunk is not None else [self.name]

    def live_workers(self) -> list[str]:
        """This process (until excluded)."""
        return [] if self._stopped else [self.name]

    def can_grow(self) -> bool:
        """No other worker can appear."""
        return False

    def submit(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> None:
        """Queue the chunk; the next `poll` renders it."""
        self._chunk = (chunk_id, job, list(inputs), ctx)

    def poll(self, timeout: float) -> list[Event]:
        """Render the queued chunk (whatever `timeout` says: it runs here, to its end)."""
        if self._chunk is None:
            return []
        chunk_id, job, inputs, ctx = self._chunk
        events: list[Event] = []

        def written(frame: int, seconds: float) -> None:
            events.append(FrameWritten(self.name, chunk_id, frame, seconds))

        try:
            result = run_chunk(chunk_id, job, inputs, ctx, on_frame=written)
        except Exception as exc:  # run_chunk reports frame errors itself; this is the rest
            events.append(Lost(self.name, chunk_id, f"{type(exc).__name__}: {exc}"))
        else:
            events.append(Done(self.name, chunk_id, result))
        finally:
            self._chunk = None
        return events

    def stop_worker(self, worker: str, reason: str) -> None:
        """Excluded (it failed too often): no further chunk runs here."""
        self._stopped = True

    def close(self, interrupted: bool = False) -> None:
        """Nothing to shut down; the worker's cached scene goes with the process."""
        self._chunk = None
