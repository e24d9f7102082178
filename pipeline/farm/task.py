"""The one task both executors run: claim each frame of a chunk, skip it if it is already
complete, render the rest through `render_frames` (the worker's first-frame cache stays in
its process), release the claims. Only small `ChunkResult`s travel back."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

from ..errors import DiskFaultError
from ..frame_output import confined
from ..identity import complete_as
from ..bake import BakedFrame
from ..render.worker.job import FrameResult, RenderJob, render_frames, worker_id
from .claims import Claimant, claim_path, release, remove_partials, try_claim


@dataclass(frozen=True)
class TaskContext:
    """What a task needs besides the job: the run's id (claims), frame paths by frame,
    whether complete frames are skipped, and the claim staleness limit."""

    run_id: str
    paths: dict[int, str]
    resume: bool = True
    stale_after_s: float = 1800.0

    def only(self, frames: Sequence[int]) -> "TaskContext":
        """The context of one chunk: the paths of its own frames. Each task travels with
        its context, so what a task carries stays O(its frames), not O(the job's frames)."""
        return replace(self, paths={f: self.paths[f] for f in frames})


@dataclass
class ChunkResult:
    """Per-frame results, frames another render holds, frames found already complete."""

    chunk_id: int
    worker: str
    results: list[FrameResult] = field(default_factory=list)
    held_elsewhere: dict[int, str] = field(default_factory=dict)
    already_done: list[int] = field(default_factory=list)
    seconds: float = 0.0
    disk_fault: str | None = None  # the disk refused a write: the chunk stopped there
    frame_bytes: dict[int, bytes] = field(default_factory=dict)  # ship mode: finished EXRs travelling home


def claim_frame(job: RenderJob, baked: BakedFrame, ctx: TaskContext, me: Claimant, out: ChunkResult) -> bool:
    """Claim one frame of a chunk before rendering it: True when this process now holds its
    claim and the frame needs rendering. Otherwise `out` says why not (a link leading out of
    the output folder, a claim another render holds, or a complete frame with `resume`,
    whose claim is released again). A disk refusing the claim raises DiskFaultError. Run by
    the worker (`run_chunk`) or, for a shipped job, by the client (`transfer.home.claim_home`)."""
    path = ctx.paths[baked.frame]
    if not (confined(job.output_dir, path) and confined(job.output_dir, claim_path(path))):
        # a link planted in the output folder after the job's checks: nothing is written through it
        out.results.append(FrameResult(baked.frame, "", False, worker_id(), error=f"{path}: a link on its way leads outside the output folder {job.output_dir}; not written"))
        return False
    ok, holder = try_claim(path, me, ctx.stale_after_s)
    if not ok:
        owner = holder or {}
        out.held_elsewhere[baked.frame] = f"{owner.get('host', '?')}:{owner.get('pid', '?')} (run {owner.get('run_id', '?')})"
        return False
    try:
        remove_partials(path)
        if ctx.resume and complete_as(path, job.identity(baked)):
            out.already_done.append(baked.frame)
            release(path, ctx.run_id)
            return False
    except BaseException:
        release(path, ctx.run_id)
        raise
    return True


def run_chunk(chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext, on_frame: Callable[[int, float], None] | None = None) -> ChunkResult:
    """Render one chunk in this worker process (local or Dask). `on_frame(frame, seconds)`
    is called as each frame is written (seconds: its setup, render, denoise and write) (the local executor tells the farm at once, so
    progress moves per frame, not per chunk)."""
    t0 = time.perf_counter()
    me = Claimant.here(ctx.run_id)
    out = ChunkResult(chunk_id=chunk_id, worker=worker_id())
    for baked in inputs:
        path = ctx.paths[baked.frame]
        try:
            if not claim_frame(job, baked, ctx, me, out):
                continue
        except DiskFaultError as exc:
            out.disk_fault = str(exc)  # the farm stops the job; the rest of the chunk waits
            break
        try:
            results = render_frames(job, [baked], {baked.frame: path})  # the path claimed and checked above
            out.results.extend(results)
            fault = next((r.error for r in results if getattr(r, "disk_fault", False)), None)
            if fault:
                out.disk_fault = fault
                break
            if on_frame is not None and all(r.ok for r in results):
                on_frame(baked.frame, sum(r.setup_s + r.render_s + r.denoise_s + r.write_s for r in results))
        finally:
            release(path, ctx.run_id)
    out.seconds = time.perf_counter() - t0
    return out
