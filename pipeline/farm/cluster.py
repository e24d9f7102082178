"""The Dask executor: the same chunks on a Dask distributed cluster.

Start a cluster with `dask scheduler` and one `dask worker` per machine (docs/farm.md).
Each chunk is pinned to one idle worker (`workers=[address]`, no stealing), so the farm
knows who runs what and since when, exactly as with local processes. The task is the same
`run_chunk`; its first-frame cache lives in the Dask worker process (a module-level cache
in `render.job`, alive for the worker's lifetime, reused by every chunk that worker gets),
frames are written by the worker straight into the shared output folder, and only the
small `ChunkResult` travels back. Progress moves per frame as with local workers: the task
logs a `FrameWritten` event to the scheduler as each frame is written
(`Worker.log_event`), and the client's topic subscription hands it to the farm.
"""

from __future__ import annotations

import time
import uuid
from collections import deque
from typing import Any, Sequence

from ..errors import UsageError
from ..bake import BakedFrame
from ..render.job import RenderJob
from .executor import Done, Event, FrameWritten, Lost
from .task import ChunkResult, TaskContext, run_chunk

FRAME_TOPIC = "motion-frame-written"  # the scheduler's event topic for per-frame progress


def run_chunk_reporting(chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext, topic: str) -> ChunkResult:
    """`run_chunk` on a Dask worker, logging each written frame to `topic` on the
    scheduler so the farm's progress moves per frame, not per chunk."""
    from distributed import get_worker

    worker = get_worker()

    def written(frame: int, seconds: float) -> None:
        try:
            worker.log_event(topic, {"worker": worker.address, "chunk": chunk_id, "frame": frame, "seconds": seconds})
        except Exception:  # progress is best effort; the chunk's result carries every frame
            pass

    return run_chunk(chunk_id, job, inputs, ctx, on_frame=written)


class DaskExecutor:
    """Chunks on a Dask cluster; workers that leave are seen on the next poll."""

    kind = "dask"

    def __init__(self, address: str | None = None, scheduler_file: str | None = None, connect_timeout_s: float = 30.0, wait_workers_s: float = 60.0) -> None:
        from distributed import Client

        try:
            self.client = Client(address=address, scheduler_file=scheduler_file, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise UsageError(f"--scheduler: cannot reach the Dask scheduler at {address or scheduler_file}: {exc}") from None
        self.address = self.client.scheduler.address
        try:
            self.client.wait_for_workers(1, timeout=wait_workers_s)
        except (TimeoutError, Exception) as exc:  # dask raises its own TimeoutError type
            self.client.close()
            raise UsageError(f"--scheduler: no Dask worker joined {self.address} within {wait_workers_s:g}s ({type(exc).__name__})") from None
        self._running: dict[str, tuple[Any, int]] = {}
        self._written: deque[FrameWritten] = deque()
        self._topic = f"{FRAME_TOPIC}-{uuid.uuid4().hex[:8]}"  # this run's frames only
        self.client.subscribe_topic(self._topic, self._on_frame_event)
        self._live: list[str] = []
        self._refreshed = 0.0
        self._refresh(force=True)

    def _on_frame_event(self, event: tuple[float, Any]) -> None:
        """Called on the client's event loop for each frame a worker logged."""
        msg = event[1]
        try:
            self._written.append(FrameWritten(str(msg["worker"]), int(msg["chunk"]), int(msg["frame"]), float(msg.get("seconds", 0.0))))
        except (KeyError, TypeError, ValueError):
            return

    def _refresh(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._refreshed > 0.5:
            self._live = sorted(self.client.scheduler_info(n_workers=-1)["workers"])
            self._refreshed = now

    def live_workers(self) -> list[str]:
        """The cluster's workers as last seen."""
        return list(self._live)

    def idle_workers(self) -> list[str]:
        """Live workers without a chunk of ours."""
        return [w for w in self._live if w not in self._running]

    def can_grow(self) -> bool:
        """Always: workers may join a Dask cluster at any time."""
        return True  # workers may join the cluster at any time

    def submit(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> None:
        """Run one chunk on `worker` (pinned there, no work stealing)."""
        fut = self.client.submit(
            run_chunk_reporting,
            chunk_id,
            job,
            list(inputs),
            ctx,
            self._topic,
            key=f"motion-chunk-{chunk_id}-{uuid.uuid4().hex[:8]}",
            workers=[worker],
            allow_other_workers=False,
            pure=False,
            retries=0,  # the farm retries, on another worker
        )
        self._running[worker] = (fut, chunk_id)

    def poll(self, timeout: float) -> list[Event]:
        """Wait up to `timeout` s; the frames written, the chunks finished or failed since,
        and workers that joined or left."""
        from distributed import wait

        futs = [f for f, _ in self._running.values()]
        if not futs:
            time.sleep(timeout)
        # wait for a finished chunk, in slices so that a frame a worker logged wakes us too
        deadline = time.monotonic() + timeout
        while futs and not self._written and (left := deadline - time.monotonic()) > 0:
            try:
                wait(futs, timeout=min(left, 0.1), return_when="FIRST_COMPLETED")
                break
            except Exception:  # a timeout (dask's own TimeoutError type)
                continue
        self._refresh()
        events: list[Event] = []
        while self._written:
            events.append(self._written.popleft())
        for w, (fut, chunk_id) in list(self._running.items()):
            if fut.status == "finished":
                del self._running[w]
                events.append(Done(w, chunk_id, fut.result()))
            elif fut.status in ("error", "cancelled", "lost"):
                del self._running[w]
                try:
                    exc = fut.exception(timeout=1)
                    why = f"{type(exc).__name__}: {exc}"
                except Exception as e:  # cancelled futures raise on .exception()
                    why = f"task {fut.status} ({type(e).__name__})"
                events.append(Lost(w, chunk_id, f"on {w}: {why}"))
            elif w not in self._live:
                del self._running[w]
                fut.cancel()
                events.append(Lost(w, chunk_id, f"worker {w} left the cluster"))
        return events

    def stop_worker(self, worker: str, reason: str) -> None:
        """Cancel the worker's chunk; on a timeout restart its process (a running task cannot be cancelled)."""
        entry = self._running.pop(worker, None)
        if entry is not None:
            entry[0].cancel()
        if reason == "timeout":
            # a running Python task cannot be cancelled: restart that worker's process
            try:
                self.client.restart_workers([worker], timeout=30, raise_for_error=False)
            except Exception:
                pass
            self._refresh(force=True)

    def close(self, interrupted: bool = False) -> None:
        """Cancel what is still running (restarting busy workers when interrupted) and close the client."""
        for fut, _ in self._running.values():
            fut.cancel()
        if interrupted and self._running:
            # tasks already running finish their frame (atomic writes, claims released);
            # restarting the workers stops them sooner
            try:
                self.client.restart_workers(list(self._running), timeout=10, raise_for_error=False)
            except Exception:
                pass
        self._running.clear()
        try:
            self.client.unsubscribe_topic(self._topic)
        except Exception:  # the connection may already be gone
            pass
        self.client.close()
