"""Run a job's chunks on an executor: the local process pool (default) or a Dask cluster,
driven by the scheduler until every chunk is done, failed everywhere, or Ctrl-C stops it
cleanly. What to run (frames, baked inputs, the job) is the shot stage's
(motion.pipeline.shot), its size sizing.py's; this module drives the executor.

drjit is imported in this process only for a small job that the shot stage runs inline
(farm/inline.py); otherwise workers are spawned (or are Dask workers) and import it
themselves.
"""

from __future__ import annotations

from pathlib import Path
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..bake import BakedFrame
from ..errors import UsageError
from ..render.worker.job import RenderJob
from .config import FarmConfig
from .progress import Progress

if TYPE_CHECKING:  # (imported where a chunk runs: a run with none never loads the scheduler)
    from .scheduler import Scheduler
    from .task import TaskContext

def run_chunks(
    chunk_list: list[list[int]],
    job: RenderJob,
    by_frame: Mapping[int, BakedFrame],
    ctx: TaskContext,
    cfg: FarmConfig,
    progress: Progress,
    *,
    scheduler: str | None,
    workers: int,
    threads: int | None,
    inline: bool = False,
) -> tuple[Scheduler | None, bool]:
    """Render the chunks on a Dask cluster (`scheduler`) or on at most `workers` local
    processes; returns the scheduler (None when there was nothing to run) and whether
    Ctrl-C interrupted the run (the executor is then closed at once and the chunks in
    flight settled as not rendered)."""
    executor: Any = None
    interrupted = False
    sched: Scheduler | None = None
    try:
        if chunk_list:
            from .scheduler import Scheduler

            if scheduler:
                from .address import scheduler_target
                from .cluster import DaskExecutor

                executor = DaskExecutor(**scheduler_target(scheduler), gpu=job.variant.startswith("cuda"))
                progress.note(f"  executor: dask at {executor.address}, {len(executor.live_workers())} workers")
                assets = getattr(job.shipped, "assets", None)
                if assets is not None:
                    mb = sum(a.size for a in assets) / 1e6
                    progress.note(f"  transfer: ship (no shared disk): the job carries its scene and {len(assets)} files ({mb:.1f} MB), each sent once per worker; frames come home")
            elif inline:
                from .inline import InlineExecutor

                executor = InlineExecutor()
                progress.note(f"  executor: inline (a small job: this process, no worker started) x {threads} threads")
            else:
                from .local import LocalExecutor
                from .sizing import worker_devices

                executor = LocalExecutor(min(workers, len(chunk_list)), devices=worker_devices(job.variant))
                gpus = f" on GPUs {', '.join(executor.devices)}" if executor.devices else ""
                progress.note(f"  executor: local, {executor.n} worker processes x {threads} threads{gpus}")
            sched = Scheduler(executor, job, by_frame, ctx, cfg, notify=progress.event, no_worker_grace_s=120.0 if scheduler else 0.0)
            with progress:
                sched.run(chunk_list)
    except KeyboardInterrupt:
        interrupted = True
        if executor is not None:
            executor.close(interrupted=True)
            executor = None
        if sched is not None:
            sched.abandon()
            sched.settle_interrupted()
    finally:
        if executor is not None:
            executor.close()
    return sched, interrupted
