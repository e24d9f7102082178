"""`motion render`: scene -> baked motion -> frames on disk (-> deliverables), on local
worker processes or a Dask cluster (docs/farm.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from motion.cli.options import GivenPath, MAX_TASK_TIMEOUT_S, FiniteFloat
from motion.pipeline.errors import UsageError

if TYPE_CHECKING:
    from motion.pipeline.shot import RenderRequest


def _resolution(value: str | None) -> tuple[int, int] | None:
    if value is None:
        return None
    try:
        w, h = (int(x) for x in value.lower().split("x"))
    except ValueError:
        raise UsageError(f"--resolution expects WIDTHxHEIGHT such as 640x360, got {value!r}") from None
    if w < 1 or h < 1:
        raise UsageError(f"--resolution must be positive, got {value!r}")
    return (w, h)


@click.command("render")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output_dir", type=GivenPath(file_okay=False, path_type=Path), help="Output folder (default: the scene's output.directory, else out/<name>).")
@click.option("--frames", "frames_spec", help="Frames: 0-119, 0-119x2 (every 2nd), 1,5,9 or mixes (default: the scene's timeline).")
@click.option("--shard", help="I/N: render only the I-th (1-based) of N balanced parts of the frames (CI matrix, farm nodes).")
@click.option("--preset", help="Render preset: ci-smoke, preview, final, or a path to a preset .yaml.")
@click.option("--spp", type=click.IntRange(min=1), help="Samples per pixel (overrides preset and scene).")
@click.option("--seed", type=click.IntRange(min=0, max=2**31 - 1), help="Render seed (overrides preset and scene render.seed; changes the noise, not the picture).")
@click.option("--resolution", help="WIDTHxHEIGHT (overrides preset and scene).")
@click.option("--motion-blur", type=click.Choice(["stochastic", "subframes", "off"]), help="Motion-blur mode.")
@click.option("--denoise/--no-denoise", "denoise", default=None, help="Denoise each frame with Intel Open Image Denoise, albedo + normal guides (default: the preset's / scene's render.denoise).")
@click.option("--temporal", type=click.Choice(["off", "reproject"]), help="Temporal stability of denoised frames: reproject neighbours by motion vectors and blend where they agree (docs/denoise.md).")
@click.option("--aov", "aovs", multiple=True, type=click.Choice(["depth", "normal", "motion", "albedo"]), help="Extra EXR layer (repeatable): depth (Z), normal (N), motion, albedo. Replaces the scene's output.aovs.")
@click.option("--variant", type=click.Choice(["auto", "llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb"]), help="Mitsuba variant (default: auto).")
@click.option("--motion", "motion_file", type=click.Path(dir_okay=False, path_type=Path), help="Baked motion from `motion bake` (.json/.npz) instead of baking here.")
@click.option("--workers", type=click.IntRange(min=1), help="Local worker processes (default: one per core on the CPU, one per GPU on cuda_ad_rgb; at most 8 and at most one per frame); drjit threads are divided among them.")
@click.option("--scheduler", help="Dask cluster: tcp://HOST:PORT or a scheduler file (instead of local workers).")
@click.option("--transfer", type=click.Choice(["auto", "ship", "shared"]), default="auto", show_default=True, help="With --scheduler: ship the parsed scene and its assets to the workers and bring frames home (no shared disk), use the shared folders, or auto (ship when a worker cannot read the scene file).")
@click.option("--threads", type=click.IntRange(min=1), help="drjit threads per worker (default: cores // workers locally, all cores on a Dask worker).")
@click.option("--chunk-size", type=click.IntRange(min=1), help="Frames per task (default: from frame and worker count; configs/farm.yaml).")
@click.option("--retries", type=click.IntRange(min=0), help="Extra attempts for a failed chunk (default: configs/farm.yaml).")
@click.option("--task-timeout", "task_timeout_s", type=FiniteFloat(min=0, min_open=True, max=MAX_TASK_TIMEOUT_S), help="Seconds before a chunk is cancelled and retried (at most a week).")
@click.option("--resume/--no-resume", default=True, show_default=True, help="Skip frames already complete with this scene, motion and settings.")
@click.option("--overwrite", is_flag=True, help="Re-render every selected frame, replacing complete ones.")
@click.option("--report", "report_path", type=GivenPath(dir_okay=False, path_type=Path), help="Where to write the JSON report (default: OUTPUT/render-report.json).")
@click.option("--progress/--no-progress", "progress", default=None, help="Live progress bar (default: only on a terminal).")
@click.option("--check", is_flag=True, help="Render nothing: verify every selected frame is complete (exit 3 if not).")
@click.option("--no-cache", is_flag=True, help="Naive path for comparison: a fresh Mitsuba scene for every frame.")
@click.option("--deliver", "deliver_spec", help="After the last frame, assemble the shot's deliverables (a new version when its frames changed): 24p,60i,50i,review,review25,contact.")
@click.option("--deliver-frames", "deliver_frames", help="Make the deliverables of these frames (A-B) instead of the whole shot, named apart.")
@click.option("--exposure", type=float, default=0.0, show_default=True, help="Deliverables' view transform: exposure in stops.")
@click.option("--ocio", "ocio_config", help="Deliverables' view transform: an OCIO config file or built-in ocio://NAME (default: ocio://cg-config-latest, ACES 2.0 SDR on sRGB; none: the plain sRGB curve).")
@click.option("--ocio-display", help="OCIO display (default: the config's default).")
@click.option("--ocio-view", help="OCIO view (default: the display's default).")
@click.option("--dry-run", is_flag=True, help="Say what would be rendered (frames, chunks, executor, outputs) and write nothing.")
@click.option("--json", "as_json", is_flag=True, help="Print the plan (--dry-run) or the run's summary as JSON on stdout.")
@click.option("--fields", "fields", type=click.Choice(["60i", "50i"]), help="Render the video's fields directly (each at its own instant and shutter, only its rows) into OUT/fields/ and weave them into interlaced frames and a movie in OUT; --frames then counts interlaced frames.")
@click.option("--field-order", type=click.Choice(["tff", "bff"]), default="tff", show_default=True, help="With --fields: which field of each frame is first in time.")
@click.option("--compare", "compare_ref", type=click.Path(file_okay=False, path_type=Path), help="After the frames, compare them with the references in this folder (motion compare; reports in OUTPUT/compare/; exit 1 if one differs).")
@click.option("--allow-different-settings", is_flag=True, help="Kept for scripts: with --compare, frames made differently are always compared, each difference a note.")
def render(
    scene: Path,
    output_dir: Path | None,
    frames_spec: str | None,
    shard: str | None,
    preset: str | None,
    spp: int | None,
    seed: int | None,
    resolution: str | None,
    motion_blur: str | None,
    denoise: bool | None,
    temporal: str | None,
    aovs: tuple[str, ...],
    variant: str | None,
    motion_file: Path | None,
    workers: int | None,
    scheduler: str | None,
    transfer: str,
    threads: int | None,
    chunk_size: int | None,
    retries: int | None,
    task_timeout_s: float | None,
    resume: bool,
    overwrite: bool,
    report_path: Path | None,
    progress: bool | None,
    check: bool,
    no_cache: bool,
    deliver_spec: str | None,
    deliver_frames: str | None,
    exposure: float,
    ocio_config: str | None,
    ocio_display: str | None,
    ocio_view: str | None,
    dry_run: bool,
    as_json: bool,
    fields: str | None,
    field_order: str,
    compare_ref: Path | None,
    allow_different_settings: bool,
) -> None:
    """Render SCENE's frames to OpenEXR files."""
    from motion.pipeline.shot import DeliverView, RenderRequest

    request = RenderRequest(
        scene=scene, output_dir=output_dir, frames_spec=frames_spec, shard=shard, preset=preset, motion_file=motion_file, report=report_path,
        render_overrides={**_render_overrides(spp, resolution, motion_blur, variant, denoise, temporal), "seed": seed},
        output_overrides={"aovs": list(dict.fromkeys(aovs)) or None},
        cache=not no_cache, resume=resume, overwrite=overwrite, progress=progress, check=check, dry_run=dry_run,
        deliver=deliver_spec, deliver_frames=deliver_frames,
        deliver_view=DeliverView(exposure=exposure, ocio_config=ocio_config, ocio_display=ocio_display, ocio_view=ocio_view),
        workers=workers, scheduler=scheduler, transfer=transfer, threads=threads, chunk_size=chunk_size, retries=retries, task_timeout_s=task_timeout_s,
        compare=None if dry_run else compare_ref,
    )
    if fields:
        from motion.pipeline.shot import run_field_render

        if dry_run or as_json or compare_ref:
            raise click.UsageError("--fields does not combine with --dry-run, --json or --compare")
        from motion.cli.main import restore_gc

        restore_gc()
        run_field_render(request, fields, field_order)
        return
    result = _run(request, as_json)
    if dry_run:
        from motion.pipeline.shot import plan_text

        click.echo(json.dumps(result, indent=2) if as_json else plan_text(result))
    elif as_json:
        click.echo(json.dumps(summary(result) if "totals" in result else result, indent=2))
    if compare_ref is not None and not dry_run:
        _compare(result, compare_ref)
    elif not dry_run and _left_nothing_running(request, result):
        from motion.cli.main import nothing_to_finish

        nothing_to_finish()  # a rerun that rendered and made nothing ends without teardown (cli/main.py)


def _left_nothing_running(request: "RenderRequest", report: dict[str, Any]) -> bool:
    """Whether a finished run started nothing that teardown would finish: no task ran (no
    worker process, no Dask client), no deliverable was made (each was up to date), no
    thread besides the main one, no child process."""
    import sys
    import threading

    executor = report.get("executor") or {}
    delivered = (report.get("deliverables") or {}).get("status") or {}
    children = sys.modules.get("multiprocessing")
    return (request.scheduler is None and executor.get("chunks") == 0 and all(v == "up to date" for v in delivered.values())
            and threading.active_count() == 1 and not (children is not None and children.active_children()))


def _render_overrides(spp: int | None, resolution: str | None, motion_blur: str | None, variant: str | None, denoise: bool | None, temporal: str | None) -> dict[str, Any]:
    """The flags that override the preset's and the scene's `render:` settings (None: not given)."""
    return {
        "spp": spp,
        "resolution": _resolution(resolution),
        "motion_blur": motion_blur,
        "variant": variant,
        "denoise": None if denoise is None else ("oidn" if denoise else "off"),
        "temporal": temporal,
    }


def _run(request: "RenderRequest", as_json: bool) -> dict[str, Any]:
    """The render's report (or plan); a job with frames that failed everywhere prints its
    summary first with --json, then raises (exit 3)."""
    from motion.cli.main import restore_gc
    from motion.pipeline.errors import IncompleteJobError
    from motion.pipeline.shot import run_render

    restore_gc()  # the pipeline's modules imported with the collector off, as validate does (cli/main.py)
    try:
        return run_render(request)
    except IncompleteJobError as err:
        if as_json and getattr(err, "report", None) is not None:
            click.echo(json.dumps(summary(err.report), indent=2))  # type: ignore[attr-defined]
        raise


def _compare(report: dict, ref_dir: Path) -> None:
    """`--compare REF`: the frames just rendered against the references (exit 1 if one
    differs); how they were made differently, as `note:` lines like `motion compare`'s."""
    from motion.pipeline.errors import FramesDifferError
    from motion.pipeline.shot.compare import compare_render

    result, written = compare_render(report, ref_dir)
    for line in result.notes:
        click.echo(f"note: {line}", err=True)
    for f in result.failed:
        click.echo(f.message(), err=True)
    click.echo(result.summary(), err=True)
    click.echo(f"compare report: {written['html']}", err=True)
    if result.failed:
        raise FramesDifferError(f"{len(result.failed)} of {len(result.frames)} frames differ from the references in {ref_dir}")


def summary(report: dict) -> dict:
    """The run's summary for `--json`: where things are and the totals (the full report is
    the file at `report`)."""
    keys = ("scene", "scene_name", "output_dir", "selection", "shard", "frames_this_job", "interrupted", "totals", "failed", "not_rendered", "deliverables", "report")
    return {k: report.get(k) for k in keys if k in report}


render.start_up_only = True  # type: ignore[attr-defined]  # the collector comes back on in _run, once the pipeline is imported
commands = [render]
