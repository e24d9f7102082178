"""Frames that come home: the client claims and resume-checks a shipped chunk's frames on
the output folder the workers cannot see (`claim_home`), a worker renders them into its own
temporary folder and returns the checked EXR bytes (`run_chunk_away`), and the client
publishes them under `-o` (`publish_home`)."""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

from ...bake import BakedFrame
from ...errors import DiskFaultError
from ...write_policy import confined, writing
from ...identity import complete_as
from ...render.worker.job import FrameResult, RenderJob
from ..claims import release
from ..task import ChunkResult, TaskContext, claim_frame


def claim_home(job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> tuple[list[BakedFrame], ChunkResult]:
    """On the client, before a shipped chunk is sent: the usual claims and resume check on
    the output folder (`task.claim_frame`), which the workers cannot see. Returns the frames
    to render remotely (claimed by this run) and a result holding the others (held by
    another render, already complete, refused); a disk fault stops there."""
    from ...render.worker.job import worker_id
    from ..claims import Claimant

    me = Claimant.here(ctx.run_id)
    pre = ChunkResult(chunk_id=-1, worker=worker_id())
    todo: list[BakedFrame] = []
    for baked in inputs:
        try:
            if claim_frame(job, baked, ctx, me, pre):
                todo.append(baked)
        except DiskFaultError as exc:
            pre.disk_fault = str(exc)
            break
    return todo, pre


def run_chunk_away(run: Callable[[int, RenderJob, Sequence[BakedFrame], TaskContext], ChunkResult], chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> ChunkResult:
    """A chunk on a worker that cannot see the output folder: `run` renders it into a
    temporary folder of the worker's own (the client holds the real claims), each finished
    EXR is read back (`complete_as`: whole, and its header carries the frame's identity) and
    its bytes go home in the result for the client to publish (`publish_home`). A disk
    fault here is this worker's own disk (its asset cache, its temporary folder): the frame
    fails with that one line and is retried on another worker; only the client's output
    disk stops the job."""
    with tempfile.TemporaryDirectory(prefix="motion-ship-") as tmp:
        here = {b.frame: str(Path(tmp) / Path(ctx.paths[b.frame]).name) for b in inputs}
        res = run(chunk_id, replace(job, output_dir=tmp), inputs, replace(ctx, paths=here, resume=False))
        by_frame = {b.frame: b for b in inputs}
        for r in res.results:
            if r.disk_fault or not r.ok:
                if r.disk_fault:
                    r.disk_fault, r.error = False, f"on worker {res.worker}: {r.error}"
                continue
            if not complete_as(r.path, job.identity(by_frame[r.frame])):
                r.ok, r.error = False, f"frame {r.frame}: the EXR written on worker {res.worker} did not read back whole; not sent"
                continue
            res.frame_bytes[r.frame] = Path(r.path).read_bytes()
        if res.disk_fault:
            done = {r.frame for r in res.results}
            res.results.extend(FrameResult(b.frame, "", False, res.worker, error=f"on worker {res.worker}: {res.disk_fault}") for b in inputs if b.frame not in done)
            res.disk_fault = None
    return res


def publish_home(pre: ChunkResult, res: ChunkResult, job: RenderJob, ctx: TaskContext) -> ChunkResult:
    """On the client: publish each frame a shipped chunk brought home at its planned path
    under the output folder, atomically and read back (pipeline/write_policy.py), release this
    run's claims, and merge what `claim_home` settled before sending. A frame reported
    written whose bytes did not arrive is failed (the farm retries it as after a lost
    worker); a disk fault on the output folder marks the result so the farm stops as for
    any disk fault."""
    res.held_elsewhere.update(pre.held_elsewhere)
    res.already_done.extend(pre.already_done)
    res.results.extend(pre.results)
    res.disk_fault = res.disk_fault or pre.disk_fault
    unsent: list[FrameResult] = []
    for r in res.results:
        data = res.frame_bytes.pop(r.frame, None)
        path = ctx.paths[r.frame]
        try:
            if res.disk_fault and r.ok:
                unsent.append(r)  # the output disk refused an earlier frame: not rendered, kept for a rerun
                continue
            if not r.ok:
                continue
            if data is None:
                r.ok, r.error = False, f"frame {r.frame}: rendered on {res.worker} but its EXR was lost on the way back"
            elif not confined(job.output_dir, path):
                r.ok, r.error = False, f"{path}: a link on its way leads outside the output folder {job.output_dir}; not written"
            else:
                with writing(path, "publishing a frame a worker sent", verify=lambda tmp, data=data: tmp.read_bytes() == data) as tmp:
                    tmp.write_bytes(data)
                r.path = path
        except DiskFaultError as exc:
            r.ok, r.error, r.disk_fault = False, str(exc), True
            res.disk_fault = str(exc)
        finally:
            release(path, ctx.run_id)
    res.frame_bytes.clear()
    res.results = [r for r in res.results if r not in unsent]
    return res
