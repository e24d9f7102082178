"""One `motion render`, as named steps: load the scene with its preset and flags, select
frames (and the shard), size the job, check before any work, bake the motion once here,
skip complete frames, run the chunks on the farm, write `render-report.json`, then the
temporal pass and the deliverables.

drjit is imported in this process only for a small job rendered inline (farm/inline.py);
otherwise workers are spawned (or are Dask workers) and import it themselves.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Callable

from ..errors import IncompleteJobError, UsageError
from ..farm.claims import Claimant, RunLock, clear_stale, new_run_id, release_run_lock, take_run_lock
from ..farm.config import FarmConfig, load_farm_config
from ..farm.selection import chunks as make_chunks
from ..farm.selection import default_chunk_size, format_frames, parse_frames, parse_shard, shard
from ..timeline import format_range
from ..farm.progress import Progress
from ..farm.report import build_report, check_writable, merge_previous, write_report, write_report_somewhere
from ..farm.run import run_chunks
from ..farm.sizing import MAX_RETRIES, MAX_THREADS, MAX_WORKERS, default_workers, threads_per_worker, worker_devices
from ..farm.task import TaskContext
from ..limits import check_env_sizes
from ..presets import Preset, load_preset, overrides_from, spread
from ..identity import MAX_PARTS, CurrentKeys, FrameIdentity, file_digests, recorded_keys, scene_file_hash, settings_digest
from ..identity.kept import KeptKeys, keep_keys, kept_keys
from ..render.worker.job import RenderJob, frame_path
from ..scene.loader import LoadedScene, load_scene
from .deliver import DeliverPlan, check_deliver, deliver_and_record, deliver_plan
from .estimate import denoised_pixels, estimate, run_inline, samples_of
from .folder_owner import check_owner, record_owner
from .estimate import record as record_cost
from .dry_run import check_only, plan, resolved_settings
from .stale import FrameStates, folder_frames, frame_states
from .request import RenderRequest

if TYPE_CHECKING:
    from ..bake import BakedFrame
    from ..farm.scheduler import Scheduler


@dataclass(frozen=True)
class Selection:
    """The frames of a render: the selection (--frames or the preset's spread of the
    timeline), the shard asked for, and this shard's part of the selection."""

    selected: list[int]
    shard_spec: tuple[int, int] | None
    frames: list[int]


# --- the steps, in the order run_render takes them -----------------------------------------


def check_request(req: RenderRequest) -> None:
    """Flags that contradict each other, refused before anything is read."""
    if req.workers is not None and req.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {req.workers}")
    if req.workers is not None and req.scheduler:
        raise UsageError("--workers is for the local executor; a Dask cluster (--scheduler) sizes itself")
    if req.transfer != "auto" and not req.scheduler:
        raise UsageError(f"--transfer {req.transfer} is for a Dask cluster (--scheduler); local workers read the scene and write frames here")
    explicit = bool(req.deliver) and req.deliver.strip().lower() != "none"  # type: ignore[union-attr]
    if explicit and req.shard:
        raise UsageError("--deliver needs every frame: assemble after all shards with --check --deliver (docs/ci-sharding.md)")
    if explicit:
        from ..deliverables import parse_formats

        parse_formats(req.deliver)  # type: ignore[arg-type]  # a wrong name fails now, not after the last frame


def load_shot(req: RenderRequest) -> tuple[Preset | None, dict[str, Any], LoadedScene]:
    """The preset, the overrides it and the flags make, and the scene loaded with them."""
    preset, _ = load_preset(req.preset) if req.preset else (None, None)
    overrides = overrides_from(preset, {"render": req.render_overrides, "output": req.output_overrides, **req.scene_overrides})
    return preset, overrides, load_scene(req.scene, overrides)


def check_denoiser(req: RenderRequest, loaded: LoadedScene) -> None:
    """A missing or broken OIDN: one line, before any frame (not for --check)."""
    if loaded.scene.render.denoise != "off" and not req.check:
        from ..render.output.denoise import check_available

        check_available()


def select_frames(req: RenderRequest, loaded: LoadedScene, preset: Preset | None) -> Selection:
    """The selection (--frames, else the preset's spread of the timeline), then this shard of it."""
    scene = loaded.scene
    timeline_frames = list(scene.timeline.timeline().frames)
    if req.frames is not None:
        selected = sorted(set(req.frames))
        outside = [f for f in selected if not scene.timeline.first <= f <= scene.timeline.last]
        if outside:
            raise UsageError(f"frames {format_frames(outside)} are outside the timeline {format_range(scene.timeline.first, scene.timeline.last)}")
    elif req.frames_spec:
        selected = parse_frames(req.frames_spec, scene.timeline.first, scene.timeline.last)
    else:
        selected = spread(timeline_frames, preset.frame_count if preset else None)
    shard_spec = parse_shard(req.shard) if req.shard else None
    frames = shard(selected, *shard_spec) if shard_spec else selected
    return Selection(selected, shard_spec, frames)


def output_folder(req: RenderRequest, loaded: LoadedScene) -> Path:
    """-o, else the scene's output.directory, else out/<scene name>."""
    return Path(req.output_dir or loaded.scene.output.directory or Path("out") / loaded.name).resolve()


def make_job(req: RenderRequest, loaded: LoadedScene, overrides: dict[str, Any], out_dir: Path, frames: list[int]) -> tuple[RenderJob, int, int | None, KeptKeys]:
    """The job every worker runs (scene, settings and their hashes, the look) and its size:
    local worker processes and drjit threads per worker; with what the cache keeps of
    its frames' identities (identity/kept.py: the look's parts come from there when kept)."""
    digest = settings_digest(loaded)
    kept = kept_keys(digest)
    if req.scheduler:
        workers = 1
    elif req.workers:
        workers = req.workers
    else:
        workers = default_workers(len(frames), len(worker_devices(loaded.scene.render.variant)))  # one per GPU on CUDA
    if req.scheduler:
        threads = req.threads  # None: each Dask worker uses its machine's cores
    else:
        threads = req.threads or threads_per_worker(workers)
    from ..identity import Order, look_hash, look_parts

    if kept.look_parts is not None:
        parts = kept.look_parts
    else:
        from ..render.translate.roles import sort_scene

        parts = look_parts(loaded, sort_scene(loaded))
    job = RenderJob(
        scene_path=str(loaded.path),
        overrides=overrides,
        output_dir=str(out_dir),
        scene_hash=scene_file_hash(loaded),
        settings_hash=digest[:16],
        cache=req.cache,
        threads=threads,
        variant=loaded.scene.render.variant,
        fields=req.fields,
        files=json.dumps(file_digests(loaded), sort_keys=True),
        look_hash=look_hash(parts),
        look_parts=json.dumps(parts, sort_keys=True) if len(parts) <= MAX_PARTS else "",
        order=Order.of(loaded.scene),
    )
    return job, workers, threads, kept


def preflight(req: RenderRequest, loaded: LoadedScene, job: RenderJob, out_dir: Path, frames: list[int]) -> None:
    """Before any work: frames land inside the output folder, the bake fits its budget,
    and the output folder and the report's folder can be written (docs/farm.md)."""
    from ..errors import OutputConfinementError, SceneError
    from ..frame_output import inside
    from ..scene.checks import bake_budget_problems

    check_env_sizes()  # $MOTION_MAX_LANES, $MOTION_ASSET_CACHE_CAP
    named = [("scene file", loaded.path), ("output folder", out_dir), *[("frame file", frame_path(job, loaded, f)) for f in frames[:1]],
             ("--report", req.report), ("--motion file", req.motion_file)]
    for what, path in named:
        try:
            str(path).encode("utf-8")
        except UnicodeEncodeError:  # bytes that are not UTF-8 in a name (Python keeps them as lone surrogates)
            shown = os.fsencode(str(path)).decode("utf-8", "backslashreplace")
            raise UsageError(f"{what} {shown}: the name is not UTF-8 text; frame headers and reports cannot hold it (rename it)") from None
    from ..cache import check_cache_root

    check_cache_root()  # $MOTION_CACHE_DIR a file or not writable: one line now, not in every worker
    for flag, value, limit in (("--workers", req.workers, MAX_WORKERS), ("--threads", req.threads, MAX_THREADS), ("--retries", req.retries, MAX_RETRIES)):
        if value is not None and value > limit:
            raise UsageError(f"{flag} {value}: the limit is {limit}")
    if frames and not inside(out_dir, frame_path(job, loaded, frames[0])):
        raise OutputConfinementError(f"frame {frames[0]} would be written to {frame_path(job, loaded, frames[0])}, outside the output folder {out_dir}")
    from ..farm.claims import CLAIM_DIR
    from ..frame_output import confined

    for folder in sorted({frame_path(job, loaded, f).parent for f in frames}):
        for target in (folder / "x.exr", folder / CLAIM_DIR / "x.claim"):
            if not confined(out_dir, target):
                link = next((p for p in [target.parent, *target.parent.parents] if p.is_symlink()), target.parent)
                raise OutputConfinementError(f"{link} is a link to {link.resolve()}, outside the output folder {out_dir}: frames and claims are written only inside it")
    problem = worker_memory_problem(loaded)
    if problem is not None:
        raise SceneError([problem])
    if not req.motion_file:
        problems = bake_budget_problems(loaded.scene, loaded.source, len(frames))
        if problems:
            raise SceneError(problems)
    if req.compare is not None:
        from .compare import check_compare

        check_compare(req.compare, out_dir, tuple(loaded.scene.render.resolution))  # the references and OUTPUT/compare/, before the frames
    if req.check or req.dry_run:
        return  # --check and --dry-run write nothing
    check_writable(out_dir, "output folder")
    if req.report is not None:
        check_writable(Path(req.report).resolve().parent, f"--report {req.report}: folder")


def worker_memory_problem(loaded: LoadedScene) -> Any:
    """A frame whose render pass cannot fit the address space a worker may use (RLIMIT_AS,
    which workers inherit), located at render.resolution: found here, not as a
    std::bad_alloc on every attempt after the bake (docs/scene-format.md, "a render pass")."""
    from ..limits import FRAME_BYTES_PER_PIXEL, PASS_BYTES_PER_LANE, WORKER_BASE_BYTES, address_space_limit, pass_lanes

    limit = address_space_limit()
    if limit is None:
        return None
    render = loaded.scene.render
    width, height = render.resolution
    lanes = pass_lanes(width, height, render.spp)
    need = WORKER_BASE_BYTES + PASS_BYTES_PER_LANE * lanes + FRAME_BYTES_PER_PIXEL * width * height
    if need <= limit:
        return None
    return loaded.source.problem(("render", "resolution"), f"{width}x{height} needs about {need / 1e9:.1f} GB for a worker ({lanes} sample lanes a "
                                 f"pass, at most $MOTION_MAX_LANES, and the frame's {width * height} pixels); this process may use "
                                 f"{limit / 1e9:.1f} GB of address space (ulimit -v): lower the resolution or $MOTION_MAX_LANES, or raise the limit")


def warn_variant(req: RenderRequest, loaded: LoadedScene) -> None:
    """The local workers will make the same variant choice (a cached probe): warn here,
    once, rather than once per worker. Probing runs in subprocesses: no drjit import here."""
    if req.scheduler:
        return
    from .. import variant as variant_mod

    choice = variant_mod.choose(loaded.scene.render.variant)
    if choice.fallback:
        variant_mod.warn_fallback(choice)


def motion_inputs(req: RenderRequest, loaded: LoadedScene, sel: Selection) -> Sequence[BakedFrame]:
    """The worker input of every frame of this shard: simulated over the whole selection
    and baked for the shard here, or read from the --motion file."""
    from ..farm.frame_inputs import baked_inputs, file_inputs, simulation_for

    if req.motion_file:
        return file_inputs(loaded, req.motion_file, sel.frames)
    from ..farm.progress import BakeProgress

    with BakeProgress(live=req.progress) as shown:
        simulation = simulation_for(loaded, sel.selected, on_progress=shown.simulated)
        inputs = baked_inputs(loaded, sel.frames, simulation)
        shown.baked(len(sel.frames))
    return inputs


def complete_frames(req: RenderRequest, loaded: LoadedScene, job: RenderJob, out_dir: Path, paths: dict[int, str], keys: Mapping[int, FrameIdentity],
                    decode: bool = True) -> FrameStates:
    """The frames on disk: those --resume keeps (complete and of this run's identity: its
    look and their own motion) and the stale ones this run replaces, each with the reason
    (shot/stale.py). `keys`: this run's identity of each frame on disk (from the bake, the
    cache or the headers: a frame without one, which appeared since, is not counted).
    Existing frames with neither --resume nor --overwrite are a UsageError; `decode` as
    stale.frame_states'."""
    existing = [f for f in paths if os.path.exists(paths[f])]
    if not req.resume and not req.overwrite and existing:
        raise UsageError(f"{out_dir}: frames {format_frames(existing)} exist; pass --resume to keep complete ones or --overwrite to re-render them")
    if req.overwrite:
        return FrameStates(complete=[], stale={f: "--overwrite" for f in existing})
    from ..identity import part_names
    from ..identity.kept import keep_whole, whole_frames

    existing = [f for f in existing if f in keys]
    now = CurrentKeys(loaded.scene, json.loads(job.files or "{}"), json.loads(job.look_parts or "{}"), part_names(loaded))
    whole = whole_frames(out_dir) if decode and existing else None
    states = frame_states(existing, paths, keys, now, decode, whole)
    if whole is not None:
        keep_whole(out_dir, whole)
    return states


def known_keys(req: RenderRequest, s: RunSetup, paths: dict[int, str]) -> dict[int, FrameIdentity] | None:
    """This run's identity of each frame on disk without a bake, or None when the run must
    bake to know them: with --check, as the headers record them when every one says it was
    made from this version (identity.recorded_keys); else as the cache keeps them for this
    settings digest and code (identity/kept.py) when it keeps every one. Never with
    --motion (a file's motion is not the scene's)."""
    if req.motion_file:
        return None
    job = s.job
    if req.check:
        recorded = recorded_keys(paths, s.frames, job.settings_hash, job.look)
        if recorded is not None:
            return recorded
    kept = s.kept
    if kept is None or req.overwrite or kept.look_parts is None or json.dumps(kept.look_parts, sort_keys=True) != job.look_parts:
        return None
    existing = [f for f in s.frames if os.path.exists(paths[f])]
    if not all(f in kept.frames for f in existing):
        return None
    return {f: kept.frames[f] for f in existing}


INLINE_MAX_WORK_S = 1.5  # estimated seconds of warm frames under which a job renders in this process


def choose_inline(req: RenderRequest, cost: dict[str, Any], todo: list[int]) -> bool:
    """Whether the job's frames are cheaper to render here than to spread over spawned
    workers: each worker costs an import of the stack and a cold scene build (docs/farm.md,
    "Tasks, executors, threads") and parallel workers save at most the frames' own time, so a job whose
    frames are estimated at under INLINE_MAX_WORK_S renders inline (farm/inline.py). Not
    with --workers (processes asked for), --scheduler, --fields, or
    $MOTION_EXECUTOR=local; $MOTION_EXECUTOR=inline forces it."""
    forced = os.environ.get("MOTION_EXECUTOR", "").strip().lower()
    if req.scheduler or req.fields or forced == "local" or not todo:
        return False
    if forced == "inline":
        return True
    if req.workers is not None:
        return False
    return cost["warm_frame_s"] * len(todo) <= INLINE_MAX_WORK_S


def summary_line(label: str, totals: dict[str, Any], report_path: Path | None) -> str:
    """The run's one-line summary; interrupted frames are "not rendered", never failed."""
    not_rendered = f", {totals['not_rendered']} not rendered (interrupted)" if totals.get("not_rendered") else ""
    return (
        f"motion: {label}: {totals['rendered']} rendered, {totals['skipped']} skipped, {totals['done_elsewhere']} by another job, "
        f"{totals['failed']} failed{not_rendered} in {totals['wall_s']:.1f}s ({totals['frames_per_minute']:.1f} frames/min); report {report_path}"
    )


def stop_on_disk_fault(sched: Scheduler | None, report: dict[str, Any], report_path: Path | None, report_fault: str | None) -> None:
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


def raise_failures(report: dict[str, Any], frames: list[int]) -> None:
    """Frames that failed everywhere: IncompleteJobError (exit 3) listing each, carrying
    the report (for `motion render --json`)."""
    failed = report["failed"]
    if failed:
        listing = "\n".join(f"frame {f['frame']}: {f['error']} (attempts {f['attempts']})" for f in failed)
        err = IncompleteJobError(f"{len(failed)} of {len(frames)} frames failed everywhere; the others finished:\n{listing}")
        err.report = report  # type: ignore[attr-defined]  # (for `motion render --json`)
        raise err


def finish(req: RenderRequest, loaded: LoadedScene, job: RenderJob, out_dir: Path, frames: list[int], workers: int,
           report: dict[str, Any], report_path: Path | None, say: Callable[[str], None], wanted: DeliverPlan,
           paths: dict[int, str]) -> None:
    """After every frame: the temporal pass (render.temporal != off) and the deliverables
    (--deliver, else the scene's output.deliver), each recorded in the report."""
    if loaded.scene.render.temporal != "off":
        from ..render.output.temporal import temporal_pass

        report["temporal"] = temporal_pass(loaded, job, lambda f: frame_path(job, loaded, f), frames, workers=workers, log=say)
        if report_path is not None:
            write_report(report, report_path)
    say_outputs(wanted, frames, paths, say)
    if wanted and frames:
        report["deliverables"] = deliver_and_record(req, out_dir, wanted, shot_paths(loaded, out_dir, wanted), loaded.name, report, report_path, say)


def shot_paths(loaded: LoadedScene, out_dir: Path, wanted: DeliverPlan) -> dict[int, Path]:
    """Where each frame the deliverables are made of is (or would be) written: the paths
    made from the numbers once, the numbers carried with them."""
    return {f: out_dir / loaded.scene.output.frame_name(loaded.name, f) for f in wanted.frames}


def say_outputs(wanted: DeliverPlan, frames: list[int], paths: dict[int, str], say: Callable[[str], None]) -> None:
    """Where the frames are (the true paths, whatever -o said), and the deliverables the
    scene asks for that this run leaves out, with why."""
    if frames:
        first, last = paths[frames[0]], paths[frames[-1]]
        say(f"  frames: {first}" + (f" .. {Path(last).name}" if last != first else "") + f" ({len(frames)})")
    for fmt, why in wanted.skipped.items():
        say(f"  {fmt}: not made: {why} (the scene's output.deliver)")


# --- the whole render ----------------------------------------------------------------------


def run_render(req: RenderRequest) -> dict[str, Any]:
    """Render the request; returns the report. Raises IncompleteJobError (exit 3) if any
    frame failed everywhere, KeyboardInterrupt after a clean stop on Ctrl-C (or SIGTERM),
    OutputInUseError when a live run of another version of the scene renders into the same
    output folder (farm/claims.py: the run lock, held from before the bake to the end)."""
    held: list[RunLock] = []
    try:
        return _run_render(req, held)
    finally:
        for lock in held:
            release_run_lock(lock)


def version_of(req: RenderRequest, job: RenderJob) -> str:
    """What a frame of this run is made from, for the output folder's run lock: the
    settings hash (the scene with every override, each file it names by its bytes) and,
    with --motion, the motion file (its path, size and time: never read here, where a
    FIFO would hang)."""
    if not req.motion_file:
        return job.settings_hash
    path = Path(req.motion_file).resolve()
    try:
        st = path.stat()
        return f"{job.settings_hash}+{path}:{st.st_size}:{st.st_mtime_ns}"
    except OSError:
        return f"{job.settings_hash}+{path}"


@dataclass(frozen=True)
class RunSetup:
    """What a run settles before the bake, every check passed: the farm settings, the
    scene with its preset, the frames, the output folder, the deliverables wanted, the job
    and its executor's size, the scene file whose folder it takes over (if any), its id,
    and the identities of its frames the cache keeps."""

    cfg: FarmConfig
    preset: Preset | None
    loaded: LoadedScene
    sel: Selection
    out_dir: Path
    wanted: DeliverPlan
    job: RenderJob
    workers: int
    threads: int | None
    taken_from: Path | None
    run_id: str
    kept: KeptKeys | None = None  # the frames' identities the cache keeps (identity/kept.py)

    @property
    def frames(self) -> list[int]:
        """This shard's frames."""
        return self.sel.frames


@dataclass(frozen=True)
class SortedFrames:
    """After the bake: its time, each frame's motion, each frame's path, which frames are
    complete (and kept) and which render, and the folder's frames outside the timeline."""

    bake_s: float
    by_frame: Mapping[int, BakedFrame]
    paths: dict[int, str]
    states: FrameStates
    skipped: list[int]
    todo: list[int]
    foreign: list[int]
    simulation: str | None = None  # "simulated", "kept" (from an earlier run: bake/keep.py), None: no dynamics simulated here


@dataclass(frozen=True)
class Chunking:
    """How the frames to render are cut: chunk size and chunks, the cost estimate they
    were sized by, and whether the job runs inline in this process."""

    chunk_size: int
    chunk_list: list[list[int]]
    cost: dict[str, Any]
    inline: bool


def settle(req: RenderRequest, held: list[RunLock]) -> RunSetup:
    """Every check that can fail before the first task, in order; then the output folder's
    run lock, which goes into `held` (not with --check or --dry-run)."""
    cfg: FarmConfig = load_farm_config().with_overrides(retries=req.retries, task_timeout_s=req.task_timeout_s, chunk_size=req.chunk_size)
    check_request(req)
    preset, overrides, loaded = load_shot(req)
    from ..scene.checks import scene_warnings

    for warning in scene_warnings(loaded.scene):
        logging.getLogger("motion").warning(f"motion: {loaded.path}: warning: {warning}")
    check_denoiser(req, loaded)
    sel = select_frames(req, loaded, preset)
    frames = sel.frames
    out_dir = output_folder(req, loaded)
    wanted = deliver_plan(req, loaded, sel.selected if not req.shard else frames)
    if wanted:  # every check that can fail, before the first task; a declared format the shot cannot make is left out
        wanted = check_deliver(req, loaded, wanted, frames, out_dir, shot_paths(loaded, out_dir, wanted).__getitem__)
    job, workers, threads, kept = make_job(req, loaded, overrides, out_dir, frames)
    preflight(req, loaded, job, out_dir, frames)
    taken_from = check_owner(out_dir, loaded.path, req.overwrite)  # another scene file's folder: refused, one line
    if req.scheduler and not req.check:
        from ..farm.address import probe_scheduler

        probe_scheduler(req.scheduler)  # in seconds, before the bake (and in --dry-run)
        if not req.dry_run:
            from ..farm.address import scheduler_target
            from ..farm.transfer.choose import choose_transfer

            job = choose_transfer(req.transfer, scheduler_target(req.scheduler), job, loaded)  # a hostile asset path stops here
    if req.check and wanted:
        check_writable(out_dir, "output folder")  # --check --deliver writes the deliverables
    warn_variant(req, loaded)
    run_id = new_run_id()
    if not req.check and not req.dry_run:
        held.append(take_run_lock(out_dir, Claimant.here(run_id), str(loaded.path), version_of(req, job)))
    return RunSetup(cfg, preset, loaded, sel, out_dir, wanted, job, workers, threads, taken_from, run_id, kept)


def bake_and_sort(req: RenderRequest, s: RunSetup) -> SortedFrames:
    """Sort the frames (complete ones are kept, the others render) and bake the motion
    once, unless every frame's identity is known without it and nothing renders; frames in
    the folder outside the timeline are foreign (a warning)."""
    loaded, out_dir, frames, job = s.loaded, s.out_dir, s.frames, s.job
    paths = {f: str(frame_path(job, loaded, f)) for f in frames}
    keys = known_keys(req, s, paths)
    # --check --deliver: the deliverables decode every frame, so the check reads headers and chunk tables
    decode = not (req.check and s.wanted and set(frames) <= set(s.wanted.frames))
    states = complete_frames(req, loaded, job, out_dir, paths, keys, decode) if keys is not None else None
    from ..bake.keep import STORE as KEPT

    kept_before = KEPT.stats["hits"]
    must_bake = states is None or (not req.check and len(states.complete) < len(frames))
    t0 = time.perf_counter()
    inputs = motion_inputs(req, loaded, s.sel) if must_bake else []
    bake_s = time.perf_counter() - t0
    simulation: str | None = None
    by_frame: Mapping[int, BakedFrame] = {}  # nothing baked: no frame renders (the motion and bake modules stay unimported)
    if must_bake:
        from ..bake import by_number
        from ..motion import has_dynamics

        if not req.motion_file and s.sel.selected and has_dynamics(loaded):
            simulation = "kept" if KEPT.stats["hits"] > kept_before else "simulated"
        by_frame = by_number(inputs)  # each frame made from the bake's arrays when a task needs it
    if must_bake and not req.motion_file:
        baked = {f: job.identity(by_frame[f]) for f in frames}
        if s.kept is not None and job.look_parts:
            keep_keys(s.kept, json.loads(job.look_parts), job.look, baked)
        if states is None:
            states = complete_frames(req, loaded, job, out_dir, paths, baked, decode)
    elif states is None:  # --motion: each frame's identity from the file's motion
        states = complete_frames(req, loaded, job, out_dir, paths, {f: job.identity(by_frame[f]) for f in frames}, decode)
    skipped = states.complete
    todo = [f for f in frames if f not in set(skipped)]
    foreign = sorted(folder_frames(out_dir, loaded).foreign)
    if foreign:
        logging.getLogger("motion").warning(
            f"motion: {out_dir}: frames {format_frames(foreign)} lie outside the timeline {format_range(loaded.scene.timeline.first, loaded.scene.timeline.last)}: "
            "foreign, left as they are and in no deliverable")
    return SortedFrames(bake_s, by_frame, paths, states, skipped, todo, foreign, simulation)


def check_run(req: RenderRequest, s: RunSetup, sort: SortedFrames) -> dict[str, Any]:
    """--check: what a render would do, and the deliverables made from the frames there."""
    result = check_only(s.loaded.name, s.out_dir, s.frames, sort.todo, sort.paths, sort.states.stale)
    if sort.foreign:
        result["foreign"] = format_frames(sort.foreign)
    if s.wanted:
        say = Progress(total=0, live=False).log
        say_outputs(s.wanted, s.frames, sort.paths, say)
        if s.wanted:
            result["deliverables"] = deliver_and_record(req, s.out_dir, s.wanted, shot_paths(s.loaded, s.out_dir, s.wanted), s.loaded.name, result, None, say)
    return result


def cut_chunks(req: RenderRequest, s: RunSetup, sort: SortedFrames) -> tuple[RunSetup, Chunking]:
    """The chunks, sized by the cost estimate; a small job runs inline in this process,
    one worker and one chunk (the returned RunSetup says so)."""
    cfg, loaded, job, workers, threads, todo = s.cfg, s.loaded, s.job, s.workers, s.threads, sort.todo
    chunk_size = cfg.chunk_size or default_chunk_size(len(todo), workers if not req.scheduler else 2)
    if not todo and not req.dry_run:  # nothing renders: nothing reads an estimate (the inline choice, the progress bar and the cost record read it for frames rendered)
        return s, Chunking(chunk_size, make_chunks(todo, chunk_size), {}, False)
    cost = estimate(loaded.name, job.settings_hash, samples_of(loaded.scene), len(todo), workers if not req.scheduler else 1, sort.bake_s, denoised_pixels(loaded.scene))
    inline = choose_inline(req, cost, todo)
    if inline:
        workers, threads = 1, req.threads or threads_per_worker(1)
        job = replace(job, threads=threads)
        chunk_size = max(1, len(todo))
        s = replace(s, job=job, workers=workers, threads=threads)
        cost = run_inline(cost)  # run here: no worker to start (the plan's ETA and the progress bar say so)
    return s, Chunking(chunk_size, make_chunks(todo, chunk_size), cost, inline)


def report_name(req: RenderRequest, s: RunSetup) -> Path:
    """Where the report goes: --report, else the output folder's (one per shard)."""
    shard_spec = s.sel.shard_spec
    default_name = f"render-report.shard-{shard_spec[0]}-of-{shard_spec[1]}.json" if shard_spec else "render-report.json"
    return Path(req.report or s.out_dir / default_name)


def dry_run_plan(req: RenderRequest, s: RunSetup, sort: SortedFrames, c: Chunking) -> dict[str, Any]:
    """--dry-run: the plan, nothing rendered or written."""
    planned = plan(req, s.loaded, s.out_dir, s.sel.selected, s.frames, s.sel.shard_spec, sort.skipped, c.chunk_list, c.chunk_size, s.workers, s.threads, sort.paths,
                   report_name(req, s), sort.states.stale, s.wanted, resolved_settings(req, s.loaded, s.preset), c.cost)
    if c.inline:
        planned["executor"]["kind"] = "inline"
    if sort.foreign:
        planned["foreign"] = format_frames(sort.foreign)
    return planned


def open_output(req: RenderRequest, s: RunSetup, sort: SortedFrames) -> TaskContext:
    """The output folder made and recorded as this scene's, stale claims on the kept
    frames cleared; the tasks' context."""
    s.out_dir.mkdir(parents=True, exist_ok=True)
    record_owner(s.out_dir, s.loaded.path)
    if s.taken_from is not None:
        logging.getLogger("motion").warning(f"motion: {s.out_dir} held the frames of {s.taken_from}; it is now {s.loaded.path}'s folder")
    ctx = TaskContext(run_id=s.run_id, paths=sort.paths, resume=req.resume and not req.overwrite, stale_after_s=s.cfg.stale_after_s)
    clear_stale([sort.paths[f] for f in sort.skipped], s.cfg.stale_after_s)
    return ctx


def start_progress(req: RenderRequest, s: RunSetup, sort: SortedFrames, c: Chunking) -> tuple[str, Progress]:
    """The run's label and progress display, opened with the plan and the frames replaced."""
    frames, shard_spec, todo = s.frames, s.sel.shard_spec, sort.todo
    label = f"{s.loaded.name}" + (f" shard {shard_spec[0]}/{shard_spec[1]}" if shard_spec else "")
    progress = Progress(total=len(frames), already=len(sort.skipped), label=label, live=req.progress, estimate_s=c.cost["per_frame_s"] if todo else None,
                        overhead_s=c.cost["startup_s"] + c.cost["cold_extra_s"] if todo else 0.0)
    progress.note(
        f"motion: {label}: {len(frames)} frames ({format_frames(frames) or 'none'}) -> {s.out_dir}; "
        f"{len(sort.skipped)} already complete, {len(todo)} to render in {len(c.chunk_list)} chunks of <= {c.chunk_size}"
    )
    for line in sort.states.describe():
        progress.log(f"motion: {line}", logging.WARNING)
    return label, progress


def executor_info(req: RenderRequest, s: RunSetup, c: Chunking, sched: Scheduler | None) -> dict[str, Any]:
    """The report's executor: kind, size, chunks, and what crossed the network."""
    info = {"kind": "dask" if req.scheduler else ("inline" if c.inline else "local"), "workers": s.workers if not req.scheduler else None, "threads": s.threads, "scheduler": req.scheduler, "chunk_size": c.chunk_size, "chunks": len(c.chunk_list)}
    if sched is not None and hasattr(sched.ex, "transfer_stats"):
        info["transfer"] = sched.ex.transfer_stats()  # what crossed the network (docs/farm.md)
    return info


def make_report(req: RenderRequest, s: RunSetup, sort: SortedFrames, c: Chunking, sched: Scheduler | None, interrupted: bool, timings: dict[str, float]) -> dict[str, Any]:
    """The run's report, merged with the previous one's frames still there, its cost
    recorded for the next estimate."""
    loaded, job = s.loaded, s.job
    report = build_report(
        loaded=loaded,
        job=job,
        out_dir=s.out_dir,
        frames=s.frames,
        selected=s.sel.selected,
        shard_spec=s.sel.shard_spec,
        skipped=sort.skipped,
        sched=sched,
        cfg=s.cfg,
        executor_info=executor_info(req, s, c, sched),
        timings=timings,
        run_id=s.run_id,
        interrupted=interrupted,
        motion_file=str(req.motion_file) if req.motion_file else None,
    )
    report["report"] = str(report_name(req, s))
    if sort.simulation is not None:
        report["simulation"] = sort.simulation  # kept: read from an earlier run's (bake/keep.py)
    if sort.states.stale:
        report["replaced"] = [{"frame": f, "reason": why} for f, why in sorted(sort.states.stale.items())]
    timeline = loaded.scene.timeline
    # the folder's record holds the timeline's frames; others are foreign (shot/stale.py: folder_frames)
    merge_previous(report, report_name(req, s), lambda f: timeline.first <= f <= timeline.last and os.path.exists(frame_path(job, loaded, f)))
    if sort.foreign:
        report["foreign"] = format_frames(sort.foreign)
    record_cost(loaded.name, job.settings_hash, samples_of(loaded.scene), report, compiled_all=bool(c.cost.get("compiles_kernels")))
    return report


def _run_render(req: RenderRequest, held: list[RunLock]) -> dict[str, Any]:
    """run_render's steps; the run lock it takes goes into `held`."""
    t_start = time.perf_counter()
    s = settle(req, held)
    sort = bake_and_sort(req, s)
    if req.check:
        return check_run(req, s, sort)
    s, c = cut_chunks(req, s, sort)
    if req.dry_run:
        return dry_run_plan(req, s, sort, c)

    ctx = open_output(req, s, sort)
    label, progress = start_progress(req, s, sort, c)
    t_farm = time.perf_counter()
    sched, interrupted = run_chunks(c.chunk_list, s.job, sort.by_frame, ctx, s.cfg, progress, scheduler=req.scheduler, workers=s.workers, threads=s.threads, inline=c.inline)
    farm_s = time.perf_counter() - t_farm
    report = make_report(req, s, sort, c, sched, interrupted, {"bake_s": sort.bake_s, "farm_s": farm_s, "wall_s": time.perf_counter() - t_start})
    report_path, report_fault = write_report_somewhere(report, report_name(req, s), s.run_id)
    progress.log(summary_line(label, report["totals"], report_path))
    stop_on_disk_fault(sched, report, report_path, report_fault)
    if interrupted:
        raise KeyboardInterrupt
    raise_failures(report, s.frames)
    finish(req, s.loaded, s.job, s.out_dir, s.frames, s.workers, report, report_path, progress.log, s.wanted, sort.paths)
    return report
