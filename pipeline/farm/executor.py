"""What the scheduler needs from an executor (local processes or a Dask cluster)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence, Union

from ..bake import BakedFrame
from ..render.worker.job import RenderJob
from .task import ChunkResult, TaskContext


@dataclass(frozen=True)
class Done:
    """A chunk came back (its frames may still have failed individually)."""

    worker: str
    chunk_id: int
    result: ChunkResult


@dataclass(frozen=True)
class Lost:
    """A worker went away (killed, out of memory, left the cluster) or the task raised;
    `chunk_id` is the chunk it was running, if any."""

    worker: str
    chunk_id: int | None
    reason: str


@dataclass(frozen=True)
class FrameWritten:
    """A worker finished one frame of the chunk it is running (progress only: the chunk's
    `Done` still brings every frame's result)."""

    worker: str
    chunk_id: int
    frame: int
    seconds: float = 0.0  # the frame's setup, render, denoise and write in the worker


Event = Union[Done, Lost, FrameWritten]


class Executor(Protocol):
    """Runs `run_chunk` on named workers, one chunk per worker at a time."""

    kind: str

    def idle_workers(self) -> list[str]:
        """Workers alive and not running a chunk."""

    def live_workers(self) -> list[str]:
        """Every worker alive (idle or busy)."""

    def submit(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> None:
        """Start a chunk on an idle worker."""

    def poll(self, timeout: float) -> list[Event]:
        """Wait up to `timeout` seconds; return what happened."""

    def stop_worker(self, worker: str, reason: str) -> None:
        """Stop a worker (timed out or excluded); its chunk is the scheduler's to retry."""

    def can_grow(self) -> bool:
        """Whether new workers may still appear (respawn budget, a cluster that scales)."""

    def close(self, interrupted: bool = False) -> None:
        """Shut down; on interrupt stop running chunks at once."""
