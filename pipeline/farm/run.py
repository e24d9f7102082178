"""One `motion render`: load the scene with its preset and flags, select frames (and the
shard), bake their motion once here, skip complete frames, run the chunks on the local or
Dask executor, show progress, write `render-report.json`, and assemble deliverables.

drjit is never imported in this process: workers are spawned (or are Dask workers) and
import it themselves.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import IncompleteJobError, UsageError
from ..frame_output import is_complete
from ..presets import load_preset, overrides_from, spread
from ..render.job import RenderJob, expected_meta, frame_path, scene_hashes
from ..scene.loader import load_scene
from .claims import new_run_id
from .config import load_farm_config
from .frames import chunks as make_chunks
from .frames import default_chunk_size, format_frames, parse_frames, parse_shard, shard
from .progress import Progress
from .report import build_report, check_writable, write_report, write_report_somewhere
from .scheduler import Scheduler
from .task import TaskContext


@dataclass
class RenderRequest:
    """Everything `motion render` was asked to do (flags left None use the defaults)."""

    scene: Path
    output_dir: Path | None = None
    frames_spec: str | None = None
    preset: str | None = None
    render_overrides: dict[str, Any] = field(default_factory=dict)
    output_overrides: dict[str, Any] = field(default_factory=dict)  # e.g. aovs (--aov)
    cache: bool = True
    deliver: str | None = None
    deliver_view: dict[str, Any] = field(default_factory=dict)  # exposure / OCIO for the deliverables
    resume: bool = True
    overwrite: bool = False
    shard: str | None = None
    workers: int | None = None
    scheduler: str | None = None
    threads: int | None = None
    chunk_size: int | None = None
    retries: int | None = None
    task_timeout_s: float | None = None
    motion_file: Path | None = None
    report: Path | None = None
    progress: bool | None = None  # None: a live bar only on a terminal
    check: bool = False  # only verify every selected frame is complete; render nothing
    dry_run: bool = False  # only say what would be done (the plan); write nothing
    fields: str | None = None  # field order (tff/bff): the frames are fields, drawn row by parity (telecine/field_render.py)
    scene_overrides: dict[str, Any] = field(default_factory=dict)  # further sections merged over the scene (the field timeline)


def _scheduler_target(spec: str) -> dict[str, str]:
    """`tcp://host:port` (or `host:port`) -> address; an existing file -> scheduler file."""
    if "://" in spec:
        return {"address": spec}
    if Path(spec).is_file():
        return {"scheduler_file": spec}
    if ":" in spec and not spec.endswith(".json"):
        return {"address": f"tcp://{spec}"}
    raise UsageError(f"--scheduler: {spec!r} is neither tcp://HOST:PORT nor an existing scheduler file")


def _check_only(name: str, out_dir: Path, frames: list[int], todo: list[int], paths: dict[int, str]) -> dict[str, Any]:
    """`--check`: every selected frame must be complete and match (what a CI gather job
    runs before assembling deliverables)."""
    if todo:
        absent = [f for f in todo if not os.path.exists(paths[f])]
        stale = [f for f in todo if f not in set(absent)]
        why = []
        if absent:
            why.append(f"missing {format_frames(absent)}")
        if stale:
            why.append(f"incomplete or made with other settings {format_frames(stale)}")
        raise IncompleteJobError(f"{out_dir}: {len(todo)} of {len(frames)} frames of {name} not complete: " + "; ".join(why))
    from .progress import log

    log.info(f"motion: {name}: all {len(frames)} frames ({format_frames(frames)}) complete in {out_dir}")
    return {"frames": len(frames), "complete": len(frames), "output_dir": str(out_dir)}


MAX_DEFAULT_WORKERS = 8  # each worker keeps its own scene and kernels in memory


def default_workers(frames: int) -> int:
    """All local cores by default: one worker per core (each gets cores // workers drjit
    threads), no more than there are frames, at most MAX_DEFAULT_WORKERS. On 2 cores,
    2 workers x 1 thread render 1.6x faster than 1 worker x 2 threads (bench_farm)."""
    from .local import threads_per_worker

    cores = threads_per_worker(1)
    return max(1, min(cores, frames, MAX_DEFAULT_WORKERS))


MAX_WORKERS = 256  # local worker processes
MAX_THREADS = 1024  # drjit threads per worker
MAX_RETRIES = 100  # extra attempts per chunk


def _preflight(req: RenderRequest, loaded: Any, job: RenderJob, out_dir: Path, frames: list[int]) -> None:
    """Before any work: frames land inside the output folder, the bake fits its budget,
    and the output folder and the report's folder can be written (docs/farm.md)."""
    from ..errors import OutputConfinementError, SceneError
    from ..frame_output import inside
    from ..scene.checks import bake_budget_problems

    for flag, value, limit in (("--workers", req.workers, MAX_WORKERS), ("--threads", req.threads, MAX_THREADS), ("--retries", req.retries, MAX_RETRIES)):
        if value is not None and value > limit:
            raise UsageError(f"{flag} {value}: the limit is {limit}")
    if frames and not inside(out_dir, frame_path(job, loaded, frames[0])):
        raise OutputConfinementError(f"frame {frames[0]} would be written to {frame_path(job, loaded, frames[0])}, outside the output folder {out_dir}")
    if not req.motion_file:
        problems = bake_budget_problems(loaded.scene, loaded.source, len(frames))
        if problems:
            raise SceneError(problems)
    if req.check or req.dry_run:
        return  # --check and --dry-run write nothing
    check_writable(out_dir, "output folder")
    if req.report is not None:
        check_writable(Path(req.report).resolve().parent, f"--report {req.report}: folder")


def _stop_on_disk_fault(sched: Scheduler | None, report: dict[str, Any], report_path: Path | None, report_fault: str | None) -> None:
    """A disk fault ends the job with one line and exit 4: what the disk refused, how many
    frames were kept, where the report went."""
    from ..errors import DiskFaultError

    fault = sched.disk_fault if sched is not None else None
    if fault is None and report_fault is None:
        return
    totals = report["totals"]
    where = f"report {report_path}" if report_path is not None else "no report could be written anywhere"
    if report_fault is not None and report_path is not None:
        where += f" (its own place refused it: {report_fault})"
    head = fault or report_fault
    raise DiskFaultError(f"{head}; {totals['rendered'] + totals['skipped']} of {totals['frames']} frames complete and kept, {totals['failed'] + totals.get('not_rendered', 0)} not rendered; {where}")


def plan(req: RenderRequest, loaded: Any, out_dir: Path, selected: list[int], frames: list[int], shard_spec: tuple[int, int] | None,
         skipped: list[int], chunk_list: list[list[int]], chunk_size: int, workers: int, threads: int | None, paths: dict[int, str],
         report_path: Path) -> dict[str, Any]:
    """`--dry-run`: what this render would do (frames, chunks, executor, outputs), having
    loaded, validated and baked the scene and looked at the output folder; nothing is
    written."""
    from ..telecine.deliver import parse_formats

    first = paths[frames[0]] if frames else None
    deliver = {}
    if req.deliver:
        prefix = Path(first).name.split(".")[0] if first else loaded.name
        names = {"24p": f"{prefix}_24p.mov", "60i": f"{prefix}_60i.mov", "50i": f"{prefix}_50i.mov", "review": f"{prefix}_review.mp4", "contact": f"{prefix}_contact.png"}
        deliver = {fmt: str(out_dir / "deliver" / names[fmt]) for fmt in parse_formats(req.deliver)}
    return {
        "dry_run": True,
        "scene": str(loaded.path),
        "scene_name": loaded.name,
        "selection": format_frames(selected),
        "shard": f"{shard_spec[0]}/{shard_spec[1]}" if shard_spec else None,
        "frames": format_frames(frames),
        "frame_count": len(frames),
        "complete": format_frames(skipped),
        "to_render": format_frames([f for c in chunk_list for f in c]),
        "chunks": [format_frames(c) for c in chunk_list],
        "chunk_size": chunk_size,
        "executor": {"kind": "dask" if req.scheduler else "local", "workers": None if req.scheduler else min(workers, max(1, len(chunk_list))),
                     "threads": threads, "scheduler": req.scheduler},
        "outputs": {"output_dir": str(out_dir), "first_frame": first, "last_frame": paths[frames[-1]] if frames else None,
                    "report": str(report_path), "deliverables": deliver},
    }


def plan_text(p: dict[str, Any]) -> str:
    """The plan as a few lines for a person."""
    ex = p["executor"]
    how = f"dask at {ex['scheduler']}" if ex["kind"] == "dask" else f"local, {ex['workers']} worker processes x {ex['threads']} threads"
    lines = [
        f"plan for {p['scene_name']} ({p['scene']}): nothing rendered (--dry-run)",
        f"  frames:    {p['frames'] or 'none'} ({p['frame_count']})" + (f", shard {p['shard']} of {p['selection']}" if p["shard"] else ""),
        f"  complete:  {p['complete'] or 'none'} (kept)",
        f"  to render: {p['to_render'] or 'none'} in {len(p['chunks'])} chunks of <= {p['chunk_size']}",
        f"  executor:  {how}",
        f"  frames to: {p['outputs']['first_frame']} .. {p['outputs']['last_frame']}",
        f"  report:    {p['outputs']['report']}",
    ]
    for fmt, path in p["outputs"]["deliverables"].items():
        lines.append(f"  {fmt}: {path}")
    return "\n".join(lines)


def summary_line(label: str, totals: dict[str, Any], report_path: Path) -> str:
    """The run's one-line summary; interrupted frames are "not rendered", never failed."""
    not_rendered = f", {totals['not_rendered']} not rendered (interrupted)" if totals.get("not_rendered") else ""
    return (
        f"motion: {label}: {totals['rendered']} rendered, {totals['skipped']} skipped, {totals['done_elsewhere']} by another job, "
        f"{totals['failed']} failed{not_rendered} in {totals['wall_s']:.1f}s ({totals['frames_per_minute']:.1f} frames/min); report {report_path}"
    )


def run_render(req: RenderRequest) -> dict[str, Any]:
    """Render the request; returns the report. Raises IncompleteJobError (exit 3) if any
    frame failed everywhere, KeyboardInterrupt after a clean stop on Ctrl-C."""
    t_start = time.perf_counter()
    cfg = load_farm_config().with_overrides(retries=req.retries, task_timeout_s=req.task_timeout_s, chunk_size=req.chunk_size)
    if req.workers is not None and req.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {req.workers}")
    if req.workers is not None and req.scheduler:
        raise UsageError("--workers is for the local executor; a Dask cluster (--scheduler) sizes itself")
    if req.deliver and req.shard:
        raise UsageError("--deliver needs every frame: assemble after all shards (docs/ci-sharding.md)")
    if req.deliver:
        from ..telecine.deliver import parse_formats

        parse_formats(req.deliver)  # a wrong name fails now, not after the last frame
    preset, _ = load_preset(req.preset) if req.preset else (None, None)
    overrides = overrides_from(preset, {"render": req.render_overrides, "output": req.output_overrides, **req.scene_overrides})
    loaded = load_scene(req.scene, overrides)
    scene = loaded.scene
    if scene.render.denoise != "off" and not req.check:
        from ..render.denoise import check_available

        check_available()  # a missing or broken OIDN: one line, before any frame

    # frames: the selection, then this shard of it
    timeline_frames = list(scene.timeline.timeline().frames)
    if req.frames_spec:
        selected = parse_frames(req.frames_spec, scene.timeline.first, scene.timeline.last)
    else:
        selected = spread(timeline_frames, preset.frame_count if preset else None)
    shard_spec = parse_shard(req.shard) if req.shard else None
    frames = shard(selected, *shard_spec) if shard_spec else selected

    out_dir = Path(req.output_dir or scene.output.directory or Path("out") / loaded.name).resolve()
    if req.deliver:
        check_deliver(req, loaded, frames, out_dir, create=not req.dry_run)  # every check that can fail, before the first task
    scene_hash, settings_hash = scene_hashes(loaded)
    workers = 1 if req.scheduler else (req.workers or default_workers(len(frames)))
    if req.scheduler:
        threads = req.threads  # None: each Dask worker uses its machine's cores
    else:
        from .local import threads_per_worker

        threads = req.threads or threads_per_worker(workers)
    job = RenderJob(
        scene_path=str(loaded.path),
        overrides=overrides,
        output_dir=str(out_dir),
        scene_hash=scene_hash,
        settings_hash=settings_hash,
        cache=req.cache,
        threads=threads,
        variant=scene.render.variant,
        fields=req.fields,
    )

    _preflight(req, loaded, job, out_dir, frames)

    if not req.scheduler:
        # the local workers will make the same choice (cached probe); warn here, once,
        # rather than once per worker. Probing runs in subprocesses: no drjit import here.
        from .. import variant as variant_mod

        choice = variant_mod.choose(scene.render.variant)
        if choice.fallback:
            variant_mod.warn_fallback(choice)

    # motion: simulated over the whole selection, baked for this shard (or read from file)
    t0 = time.perf_counter()
    from .motion_source import baked_inputs, file_inputs, simulation_for

    if req.motion_file:
        inputs = file_inputs(loaded, req.motion_file, frames)
    else:
        from .progress import BakeProgress

        with BakeProgress(live=req.progress) as shown:
            simulation = simulation_for(loaded, selected, on_progress=shown.simulated)
            inputs = baked_inputs(loaded, frames, simulation)
            shown.baked(len(frames))
    bake_s = time.perf_counter() - t0
    by_frame = {fi.frame: fi for fi in inputs}
    paths = {f: str(frame_path(job, loaded, f)) for f in frames}

    # resume: complete frames made from this scene, motion and settings are skipped
    resume = req.resume and not req.overwrite
    existing = [f for f in frames if os.path.exists(paths[f])]
    if not req.resume and not req.overwrite and existing:
        raise UsageError(f"{out_dir}: frames {format_frames(existing)} exist; pass --resume to keep complete ones or --overwrite to re-render them")
    skipped = [f for f in frames if resume and f in existing and is_complete(paths[f], expected_meta(job, by_frame[f]))]
    todo = [f for f in frames if f not in set(skipped)]
    if req.check:
        return _check_only(loaded.name, out_dir, frames, todo, paths)
    chunk_size = cfg.chunk_size or default_chunk_size(len(todo), workers if not req.scheduler else 2)
    chunk_list = make_chunks(todo, chunk_size)
    default_name = f"render-report.shard-{shard_spec[0]}-of-{shard_spec[1]}.json" if shard_spec else "render-report.json"
    if req.dry_run:
        return plan(req, loaded, out_dir, selected, frames, shard_spec, skipped, chunk_list, chunk_size, workers, threads, paths,
                    Path(req.report or out_dir / default_name))
    out_dir.mkdir(parents=True, exist_ok=True)
    run_id = new_run_id()
    ctx = TaskContext(run_id=run_id, paths=paths, resume=resume, stale_after_s=cfg.stale_after_s)
    label = f"{loaded.name}" + (f" shard {shard_spec[0]}/{shard_spec[1]}" if shard_spec else "")
    progress = Progress(total=len(frames), already=len(skipped), label=label, live=req.progress)
    progress.log(
        f"motion: {label}: {len(frames)} frames ({format_frames(frames) or 'none'}) -> {out_dir}; "
        f"{len(skipped)} already complete, {len(todo)} to render in {len(chunk_list)} chunks of <= {chunk_size}"
    )

    executor: Any = None
    interrupted = False
    sched: Scheduler | None = None
    t_farm = time.perf_counter()
    try:
        if chunk_list:
            if req.scheduler:
                from .cluster import DaskExecutor

                executor = DaskExecutor(**_scheduler_target(req.scheduler))
                progress.log(f"  executor: dask at {executor.address}, {len(executor.live_workers())} workers")
            else:
                from .local import LocalExecutor

                executor = LocalExecutor(min(workers, len(chunk_list)))
                progress.log(f"  executor: local, {executor.n} worker processes x {threads} threads")
            sched = Scheduler(executor, job, by_frame, ctx, cfg, notify=progress.event, no_worker_grace_s=120.0 if req.scheduler else 0.0)
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
    farm_s = time.perf_counter() - t_farm

    report = build_report(
        loaded=loaded,
        job=job,
        out_dir=out_dir,
        frames=frames,
        selected=selected,
        shard_spec=shard_spec,
        skipped=skipped,
        sched=sched,
        cfg=cfg,
        executor_info={"kind": "dask" if req.scheduler else "local", "workers": workers if not req.scheduler else None, "threads": threads, "scheduler": req.scheduler, "chunk_size": chunk_size, "chunks": len(chunk_list)},
        timings={"bake_s": bake_s, "farm_s": farm_s, "wall_s": time.perf_counter() - t_start},
        run_id=run_id,
        interrupted=interrupted,
        motion_file=str(req.motion_file) if req.motion_file else None,
    )
    report["report"] = str(req.report or out_dir / default_name)
    report_path, report_fault = write_report_somewhere(report, req.report or out_dir / default_name, run_id)
    totals = report["totals"]
    progress.log(summary_line(label, totals, report_path))
    _stop_on_disk_fault(sched, report, report_path, report_fault)
    if interrupted:
        raise KeyboardInterrupt
    failed = report["failed"]
    if failed:
        listing = "\n".join(f"frame {f['frame']}: {f['error']} (attempts {f['attempts']})" for f in failed)
        err = IncompleteJobError(f"{len(failed)} of {len(frames)} frames failed everywhere; the others finished:\n{listing}")
        err.report = report  # type: ignore[attr-defined]  # (for `motion render --json`)
        raise err
    if scene.render.temporal != "off":
        from ..render.temporal import temporal_pass

        report["temporal"] = temporal_pass(loaded, job, out_dir, frames, workers=workers, log=progress.log)
        if report_path is not None:
            write_report(report, report_path)
    if req.deliver:
        report["deliverables"] = deliver_and_record(req, out_dir, report, report_path, progress.log)
    return report


def check_deliver(req: RenderRequest, loaded: Any, frames: list[int], out_dir: Path, create: bool = True) -> None:
    """What `--deliver` would find wrong after the last frame, found before the first:
    format names, the view transform (OCIO config, display, view), interlaced formats on an
    odd height, a selection with gaps (the telecine needs a gapless sequence), the movie
    encoders, a deliver folder that cannot be created."""
    from ..telecine.deliver import parse_formats
    from ..telecine.movie import CODECS, ViewTransform

    wanted = parse_formats(req.deliver or "")
    ViewTransform(**{k: v for k, v in req.deliver_view.items() if v is not None})
    height = loaded.scene.render.resolution[1]
    interlaced = [f for f in wanted if f in ("60i", "50i")]
    if interlaced and height % 2:
        raise UsageError(f"--deliver {','.join(interlaced)}: the render is {height} rows high; interlaced fields need an even height (--resolution)")
    gaps = [b for a, b in zip(frames, frames[1:]) if b != a + 1]
    if gaps and any(f != "contact" for f in wanted):
        raise UsageError(
            f"--deliver needs a gapless run of frames; this selection ({format_frames(frames)}) has gaps "
            f"(a preset's frame_count spreads frames over the timeline: pass --frames A-B)"
        )
    import av

    for name in {"24p": "prores", "60i": "prores", "50i": "prores", "review": "h264"}.keys() & set(wanted):
        codec = CODECS[{"review": "h264"}.get(name, "prores")]
        try:
            av.codec.Codec(codec.encoder, "w")
        except Exception:  # PyAV raises its own UnknownCodecError
            raise UsageError(f"--deliver {name}: this build of PyAV/FFmpeg has no {codec.encoder} encoder") from None
    try:
        if create:
            (out_dir / "deliver").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--deliver: cannot create {out_dir / 'deliver'}: {exc.strerror}") from None


def deliver_and_record(req: RenderRequest, out_dir: Path, report: dict[str, Any], report_path: Path | None, say: Any) -> dict[str, list[str]]:
    """Assemble the deliverables, print where each one is and record them in the report
    (rewritten in place)."""
    from ..telecine.deliver import deliver, parse_formats

    done = deliver(out_dir, out_dir / "deliver", parse_formats(req.deliver or ""), **{k: v for k, v in req.deliver_view.items() if v is not None})
    record: dict[str, list[str]] = {}
    for fmt, paths in done.items():
        movies = [p for p in paths if p.suffix.lower() != ".exr"]
        frames = [p for p in paths if p.suffix.lower() == ".exr"]
        record[fmt] = [str(p) for p in movies]
        if frames:
            record[f"{fmt}_frames"] = [str(frames[0].parent)]
            say(f"  {fmt}: {len(frames)} frames in {frames[0].parent}")
        for p in movies:
            say(f"  {fmt}: {p}")
    report["deliverables"] = record
    if report_path is not None:  # None: no folder would take the report (a disk fault)
        write_report(report, report_path)
    return record
