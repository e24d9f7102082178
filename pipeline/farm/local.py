"""The local executor: N worker processes on this machine, no server.

Workers are started with the 'spawn' context (never fork: drjit must not be inherited
half-initialised) and each keeps its own first-frame cache in its process. Each worker has
its own pipe, so the scheduler knows which chunk each one runs; a worker's death is seen
through its process sentinel. drjit threads are divided among the workers
(max(1, cores // N) each) so N workers never oversubscribe the cores. On a CUDA variant
each worker gets one GPU in turn (CUDA_VISIBLE_DEVICES, `sizing.worker_devices`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import socket
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from contextlib import contextmanager
from typing import Any, Iterator, Sequence

from ..bake import BakedFrame
from ..render.worker.job import RenderJob
from .executor import Done, Event, FrameWritten, Lost
from .task import TaskContext, run_chunk


def _on_term(signum: int, frame: Any) -> None:
    # SIGTERM from the farm: unwind so write_frame removes its temporary file and the
    # task releases its claims
    raise SystemExit(143)


def _worker_main(conn: Connection) -> None:
    """A worker process: render chunks until told to stop (None) or the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the farm's to handle
    signal.signal(signal.SIGTERM, _on_term)
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        chunk_id, job, inputs, ctx = msg

        def written(frame: int, seconds: float, chunk_id: int = chunk_id) -> None:
            conn.send(("frame", chunk_id, (frame, seconds)))

        try:
            reply: Any = ("done", chunk_id, run_chunk(chunk_id, job, inputs, ctx, on_frame=written))
        except Exception as exc:  # run_chunk reports frame errors itself; this is the rest
            reply = ("error", chunk_id, f"{type(exc).__name__}: {exc}")
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return


@contextmanager
def _visible_device(device: str | None) -> Iterator[None]:
    """CUDA_VISIBLE_DEVICES=device in this process's environment for the block (nothing
    changes for None)."""
    if device is None:
        yield
        return
    before = os.environ.get("CUDA_VISIBLE_DEVICES")
    os.environ["CUDA_VISIBLE_DEVICES"] = device
    try:
        yield
    finally:
        if before is None:
            del os.environ["CUDA_VISIBLE_DEVICES"]
        else:
            os.environ["CUDA_VISIBLE_DEVICES"] = before


@dataclass
class _WorkerProcess:
    """One spawned worker: its process, its pipe, the chunk it runs and its GPU."""

    name: str
    process: Any
    conn: Connection
    chunk: int | None = None
    device: str | None = None  # its GPU (CUDA_VISIBLE_DEVICES), None: all it sees


class LocalExecutor:
    """N spawned worker processes; dead ones are replaced within a respawn budget."""

    kind = "local"

    def __init__(self, workers: int, respawns: int | None = None, devices: Sequence[str] = ()) -> None:
        """`devices`: GPUs to give the workers, one each in turn (`sizing.worker_devices`); a
        replacement takes its predecessor's."""
        if workers < 1:
            raise ValueError("workers must be at least 1")
        self.n = workers
        self.devices = list(devices)
        self._ctx = mp.get_context("spawn")
        self._workers: dict[str, _WorkerProcess] = {}
        self._respawns_left = respawns if respawns is not None else 3 * workers
        self.started_at = time.perf_counter()
        for k in range(workers):
            self._spawn(self.devices[k % len(self.devices)] if self.devices else None)

    def _spawn(self, device: str | None = None) -> None:
        parent, child = self._ctx.Pipe(duplex=True)
        proc = self._ctx.Process(target=_worker_main, args=(child,), daemon=True, name="motion-farm-worker")
        with _visible_device(device):  # a spawned process starts with this environment
            proc.start()
        child.close()
        name = f"{socket.gethostname()}:{proc.pid}"
        self._workers[name] = _WorkerProcess(name=name, process=proc, conn=parent, device=device)

    @property
    def pids(self) -> list[int]:
        """Process ids of the live workers."""
        return [w.process.pid for w in self._workers.values()]

    def idle_workers(self) -> list[str]:
        """Workers without a chunk."""
        return [n for n, w in self._workers.items() if w.chunk is None]

    def live_workers(self) -> list[str]:
        """Every live worker, busy or idle."""
        return list(self._workers)

    def can_grow(self) -> bool:
        """Whether a dead worker may still be replaced (respawns left)."""
        return self._respawns_left > 0

    def submit(self, worker: str, chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> None:
        """Send one chunk to `worker`; a dead pipe is reported by the next poll."""
        w = self._workers[worker]
        w.chunk = chunk_id
        try:
            w.conn.send((chunk_id, job, list(inputs), ctx))
        except (BrokenPipeError, OSError):
            pass  # the sentinel reports the death on the next poll

    def poll(self, timeout: float) -> list[Event]:
        """Wait up to `timeout` s; the results, failures and worker deaths since."""
        by_handle: dict[Any, _WorkerProcess] = {}
        for w in self._workers.values():
            by_handle[w.conn] = w
            by_handle[w.process.sentinel] = w
        if not by_handle:
            time.sleep(timeout)
            return []
        events: list[Event] = []
        for handle in wait(list(by_handle), timeout):
            w = by_handle[handle]
            if w.name not in self._workers:
                continue
            if handle is w.conn:
                try:
                    kind, chunk_id, payload = w.conn.recv()
                except (EOFError, OSError):
                    continue  # died; the sentinel fires too
                if kind == "frame":
                    events.append(FrameWritten(w.name, chunk_id, payload[0], payload[1]))
                    continue
                w.chunk = None
                events.append(Done(w.name, chunk_id, payload) if kind == "done" else Lost(w.name, chunk_id, payload))
            else:
                w.process.join(0.1)
                code = w.process.exitcode
                reason = f"worker {w.name} died (signal {-code})" if code is not None and code < 0 else f"worker {w.name} exited with code {code}"
                events.append(Lost(w.name, w.chunk, reason))
                self._drop(w)
                if self._respawns_left > 0:
                    self._respawns_left -= 1
                    self._spawn(w.device)
        return events

    def _drop(self, w: _WorkerProcess) -> None:
        self._workers.pop(w.name, None)
        try:
            w.conn.close()
        except OSError:
            pass

    def stop_worker(self, worker: str, reason: str) -> None:
        """Kill the worker (a timeout or exclusion) and respawn one in its place while respawns are left."""
        w = self._workers.get(worker)
        if w is None:
            return
        w.process.kill()
        w.process.join(5)
        self._drop(w)
        if self._respawns_left > 0:
            self._respawns_left -= 1
            self._spawn(w.device)

    def close(self, interrupted: bool = False) -> None:
        """Stop every worker: busy ones (or all when interrupted) are terminated, idle ones
        asked to exit; any still alive after 3 s are killed."""
        workers = list(self._workers.values())
        for w in workers:
            if interrupted or w.chunk is not None:
                if w.process.is_alive():
                    w.process.terminate()  # SIGTERM: unwinds, temp files removed
            else:
                try:
                    w.conn.send(None)
                except (BrokenPipeError, OSError):
                    pass
        deadline = time.monotonic() + 3.0
        for w in workers:
            w.process.join(max(0.0, deadline - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join(2)
            self._drop(w)
