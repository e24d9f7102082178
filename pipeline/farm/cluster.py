"""The Dask executor: the same chunks on a Dask distributed cluster.

Start a cluster with `dask scheduler` and one `dask worker` per machine (docs/farm.md);
on a GPU machine one per GPU, each advertising it (`CUDA_VISIBLE_DEVICES=N dask worker
ADDRESS --nthreads 1 --resources GPU=1`): a CUDA job's chunks go only to those.
Each chunk is pinned to one idle worker (`workers=[address]`, no stealing), so the farm
knows who runs what and since when, exactly as with local processes. The task is the same
`run_chunk`; its first-frame cache lives in the Dask worker process (a module-level cache
in `render.job`, alive for the worker's lifetime, reused by every chunk that worker gets),
frames are written by the worker straight into the shared output folder, and only the
small `ChunkResult` travels back. Progress moves per frame as with local workers: the task
logs a `FrameWritten` event to the scheduler as each frame is written
(`Worker.log_event`), and the client's topic subscription hands it to the farm.

Without a shared disk (`--transfer ship`, farm/transfer/) the job carries its parsed
scene, the assets go to each worker once as scattered futures, the client claims the
frames, and the worker returns each EXR's bytes for the client to publish.
"""

from __future__ import annotations

import pickle
import time
import uuid
from collections import deque
from typing import Any, Sequence

from ..errors import UsageError
from ..bake import BakedFrame
from ..render.worker.job import RenderJob
from .executor import Done, Event, FrameWritten, Lost
from .claims import release
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


def run_chunk_shipped(chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext, topic: str, payload: dict[str, bytes]) -> ChunkResult:
    """Ship mode (`--transfer ship`): `run_chunk_reporting` into the worker's own temporary
    folder, with the asset bytes its cache lacked (`payload`: Dask resolved the scattered
    futures into bytes before the task ran); the finished EXRs' bytes return in the result
    (farm/transfer/home.py)."""
    from .transfer.home import run_chunk_away
    from .transfer.shipment import with_payload

    return run_chunk_away(lambda c, j, i, x: run_chunk_reporting(c, j, i, x, topic), chunk_id, with_payload(job, payload), inputs, ctx)


def gpu_workers(workers: dict[str, Any]) -> list[str]:
    """The addresses, sorted, of the workers (the scheduler's `scheduler_info()["workers"]`)
    that advertise at least one GPU resource."""
    return sorted(a for a, w in workers.items() if float((w.get("resources") or {}).get("GPU", 0)) >= 1)


class DaskExecutor:
    """Chunks on a Dask cluster; workers that leave are seen on the next poll."""

    kind = "dask"

    def __init__(self, address: str | None = None, scheduler_file: str | None = None, connect_timeout_s: float = 30.0, wait_workers_s: float = 60.0, gpu: bool = False) -> None:
        """Connect to the scheduler and wait for a first worker. A job that carries its
        scene (`RenderJob.shipped`, ship mode) has its assets scattered once, its chunks
        rendered away from the output folder and its frames published here on return.
        `gpu` (a CUDA variant's job): only workers that advertise a GPU resource
        (`dask worker ... --resources GPU=1`) are used, and each task asks for one."""
        import dask
        from distributed import Client

        try:
            # Dask keeps its last 1000 batches to the scheduler for debugging (each holding
            # serialized tasks): the client grew 19.5 KB per finished frame over a 100,000-frame
            # job's first 4,920 (1.1 KB without it; bench_farm's client section)
            with dask.config.set({"distributed.admin.low-level-log-length": 0}):
                self.client = Client(address=address, scheduler_file=scheduler_file, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise UsageError(f"--scheduler: cannot reach the Dask scheduler at {address or scheduler_file}: {exc}") from None
        self.address = self.client.scheduler.address
        try:
            self.client.wait_for_workers(1, timeout=wait_workers_s)
        except (TimeoutError, Exception) as exc:  # dask raises its own TimeoutError type
            self.client.close()
            raise UsageError(f"--scheduler: no Dask worker joined {self.address} within {wait_workers_s:g}s ({type(exc).__name__})") from None
        self.gpu = gpu
        self._running: dict[str, tuple[Any, int]] = {}
        self._written: deque[FrameWritten] = deque()
        self._topic = f"{FRAME_TOPIC}-{uuid.uuid4().hex[:8]}"  # this run's frames only
        self.client.subscribe_topic(self._topic, self._on_frame_event)
        self._live: list[str] = []
        self._refreshed = 0.0
        self._ship: Any = None  # transfer.shipment.Shipment of a job that carries its inputs (ship mode)
        self._claimed: dict[int, Any] = {}  # chunk id -> what the client settled before sending (ship mode)
        self._ready: list[Event] = []  # chunks settled without a task (every frame held, done or refused)
        self.task_bytes = 0  # pickled task arguments sent (job, baked frames, context, payload keys)
        self.frame_bytes = 0  # EXR bytes brought home (ship mode)
        self._refresh(force=True)
        if gpu and not self._live:
            self.client.close()
            raise UsageError(f"--scheduler: the job renders on CUDA and no worker of {self.address} advertises a GPU; start one per GPU with "
                             f"`CUDA_VISIBLE_DEVICES=N dask worker {self.address} --nthreads 1 --resources GPU=1`")

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
            self._live = gpu_workers(self.client.scheduler_info(n_workers=-1)["workers"]) if self.gpu else sorted(self.client.scheduler_info(n_workers=-1)["workers"])
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
        """Run one chunk on `worker` (pinned there, no work stealing); a shipped job's
        assets are scattered on its first chunk, once for the whole job."""
        if job.shipped is not None:
            self._submit_shipped(worker, chunk_id, job, inputs, ctx)
            return
        self._send(worker, chunk_id, run_chunk_reporting, job, list(inputs), ctx, self._topic)

    def _send(self, worker: str, chunk_id: int, task: Any, *args: Any) -> None:
        """Submit `task(chunk_id, *args)` pinned to `worker` (no stealing, no Dask retries)."""
        self.task_bytes += len(pickle.dumps(args, protocol=5))
        fut = self.client.submit(
            task,
            chunk_id,
            *args,
            key=f"motion-chunk-{chunk_id}-{uuid.uuid4().hex[:8]}",
            workers=[worker],
            allow_other_workers=False,
            pure=False,
            retries=0,  # the farm retries, on another worker
            **({"resources": {"GPU": 1}} if self.gpu else {}),
        )
        self._running[worker] = (fut, chunk_id)

    def _submit_shipped(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> None:
        """Ship mode: claim and resume-check the chunk's frames here (the worker cannot see
        the output folder), then send the frames still to render with the assets `worker`
        lacks (scattered once per job: `transfer.shipment.Shipment`)."""
        from .transfer.home import claim_home, publish_home
        from .transfer.shipment import Shipment

        if self._ship is None or self._ship.given is not job:
            self._ship = Shipment(self.client, job)
        todo, pre = claim_home(job, inputs, ctx)
        if not todo or pre.disk_fault:
            for b in todo:
                release(ctx.paths[b.frame], ctx.run_id)
            self._ready.append(Done(worker, chunk_id, publish_home(pre, ChunkResult(chunk_id, pre.worker), job, ctx)))
            return
        self._claimed[chunk_id] = (pre, ctx)
        self._send(worker, chunk_id, run_chunk_shipped, self._ship.job_future(self.client), todo, ctx.only([b.frame for b in todo]), self._topic, self._ship.payload_for(self.client, worker))

    def _finished(self, worker: str, chunk_id: int, fut: Any) -> Event:
        """A chunk's result; a shipped chunk's frames are published under the output folder first."""
        result = fut.result()
        claimed = self._claimed.pop(chunk_id, None)
        if claimed is not None:
            from .transfer.home import publish_home

            self.frame_bytes += sum(len(b) for b in result.frame_bytes.values())
            result = publish_home(claimed[0], result, self._ship.given, claimed[1])
            if any(not r.ok for r in result.results):
                self._ship.forget(worker)  # its cache may have lost an asset: ask again before its next chunk
        return Done(worker, chunk_id, result)

    def transfer_stats(self) -> dict[str, Any]:
        """What crossed the network for this job, as the report's `executor.transfer`: the
        mode, the pickled task arguments, and in ship mode the assets (their total size,
        the bytes handed to workers, each at most once per worker) and the frames brought home."""
        out: dict[str, Any] = {"mode": "shared" if self._ship is None else "ship", "task_bytes": self.task_bytes}
        if self._ship is not None:
            out.update(self._ship.stats(), frame_bytes_home=self.frame_bytes)
        return out

    def _forget(self, worker: str, chunk_id: int) -> None:
        """A shipped chunk that did not come back: its worker is asked again what it holds
        (it may have restarted); the farm releases the claims and retries the frames."""
        self._claimed.pop(chunk_id, None)
        if self._ship is not None:
            self._ship.forget(worker)

    def poll(self, timeout: float) -> list[Event]:
        """Wait up to `timeout` s; the frames written, the chunks finished or failed since,
        and workers that joined or left."""
        from distributed import wait

        futs = [f for f, _ in self._running.values()]
        if not futs and not self._ready:
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
        events: list[Event] = self._ready
        self._ready = []
        while self._written:
            events.append(self._written.popleft())
        for w, (fut, chunk_id) in list(self._running.items()):
            if fut.status == "finished":
                del self._running[w]
                events.append(self._finished(w, chunk_id, fut))
            elif fut.status in ("error", "cancelled", "lost"):
                del self._running[w]
                try:
                    exc = fut.exception(timeout=1)
                    why = f"{type(exc).__name__}: {exc}" if exc is not None else f"task {fut.status}"
                except Exception as e:  # cancelled futures raise on .exception()
                    why = f"task {fut.status} ({type(e).__name__})"
                self._forget(w, chunk_id)
                events.append(Lost(w, chunk_id, f"on {w}: {why}"))
            elif w not in self._live:
                del self._running[w]
                fut.cancel()
                self._forget(w, chunk_id)
                events.append(Lost(w, chunk_id, f"worker {w} left the cluster"))
        return events

    def stop_worker(self, worker: str, reason: str) -> None:
        """Cancel the worker's chunk; on a timeout restart its process (a running task cannot be cancelled)."""
        entry = self._running.pop(worker, None)
        if entry is not None:
            entry[0].cancel()
            self._forget(worker, entry[1])
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
