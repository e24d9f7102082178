"""A render job as workers see it, and the one task code path every executor runs.

`RenderJob` is small and picklable: the scene file, the merged overrides (preset + CLI),
the output folder and the hashes `--resume` compares. A task is `render_frames(job,
inputs)`: the worker keeps one `FrameRenderer` per job in a process-global cache (its
"first frame" layer) across all the tasks it is given, renders each frame and writes it
atomically. Only small `FrameResult`s travel back.
"""

from __future__ import annotations

import datetime as _dt
import getpass
import json
import os
import time
from dataclasses import asdict, dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Protocol, Sequence

from ...bake.records import BakedFrame
from ...field_model import parity_of
from ...frame_output import write_frame
from ...identity import FrameIdentity, Order, frame_identity, header_attributes, render_settings, scene_hashes
from ...scene.loader import LoadedScene, load_scene
from ...timeline import frame_timecode

if TYPE_CHECKING:  # the renderer (drjit, Mitsuba) is imported where a frame is rendered, not where a job is planned
    import numpy as np

    from .frame_renderer import FrameRenderer

@dataclass(frozen=True)
class RenderJob:
    """One render as every worker sees it: the scene file, the merged overrides, the
    output folder, the hashes `--resume` compares and the worker settings."""

    scene_path: str
    overrides: dict[str, Any]
    output_dir: str
    scene_hash: str
    settings_hash: str
    cache: bool = True
    threads: int | None = None
    variant: str = "auto"
    fields: str | None = None  # tff/bff: each frame is a field, only its rows are drawn
    files: str = ""  # JSON {name: digest} of the files the scene names (`scene.files.file_digests`), kept in each frame's header
    shipped: SceneSource | None = None  # ship mode: the parsed scene and its assets travel with the job
    # a frame's identity (identity/): what it looks like apart from motion (identity/look.py),
    # and the order that makes its motion's digest independent of names
    look_hash: str = ""  # empty: the settings hash stands for it
    look_parts: str = ""  # JSON {part: digest}, kept in each frame's header
    order: Order | None = None

    @property
    def look(self) -> str:
        """The look half of a frame's key (the settings hash for a job made without one)."""
        return self.look_hash or self.settings_hash

    def identity(self, baked: BakedFrame) -> FrameIdentity:
        """The identity of the frame this job renders from `baked` (what `--resume` and a
        shipped frame coming home are checked against)."""
        return frame_identity(baked, self.look, self.order)

    @property
    def key(self) -> str:
        """What a worker's cached renderer is keyed on (settings, threads, variant)."""
        return f"{self.settings_hash}:{self.threads}:{self.variant}"


class SceneSource(Protocol):
    """A job's scene carried to the worker instead of read by path (farm/transfer/shipment.py's
    ShippedScene): `checkout()` gives the parsed scene with its assets on this worker."""

    def checkout(self) -> LoadedScene:
        """The parsed scene, its asset paths resolved on this worker."""
        ...


@dataclass
class FrameResult:
    """What a worker reports for one frame: where it went, how long it took, or why it failed."""

    frame: int
    path: str
    ok: bool
    worker: str
    cold: bool = False
    setup_s: float = 0.0
    render_s: float = 0.0
    write_s: float = 0.0
    denoise_s: float = 0.0
    kernels_compiled: int = 0
    asset_cache_hits: int = 0
    error: str | None = None
    skipped: bool = False
    disk_fault: bool = False  # the error is the disk refusing the write (docs/farm.md)
    variant: str = ""  # the Mitsuba variant that rendered it
    device: str = ""  # what rendered it: cpu, or cuda:<device> (variant.device_of)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the report."""
        return asdict(self)


def frame_path(job: RenderJob, loaded: LoadedScene, frame: int) -> Path:
    """Where frame `frame` of this job is written."""
    return Path(job.output_dir) / loaded.scene.output.frame_name(loaded.name, frame)


def scene_reference(scene_path: str | Path, frame_path: str | Path) -> str:
    """The scene file as stored in a frame's header: relative to the frame's folder when
    the two share a folder below the root (a project tree with its scenes and renders can
    move as a whole; no home or checkout path leaks into deliverables), else absolute."""
    scene, folder = Path(scene_path).absolute(), Path(frame_path).absolute().parent
    try:
        common = Path(os.path.commonpath([scene, folder]))
    except ValueError:  # another drive
        return str(scene_path)
    if common == Path(common.anchor):
        return str(scene)
    return os.path.relpath(scene, folder).replace(os.sep, "/")


# --- the worker side ----------------------------------------------------------------------

_WORKER: dict[str, Any] = {}


def warm_key() -> str | None:
    """The key (`RenderJob.key`) of the job whose scene this worker process holds built, in
    memory (its renderer is reused by the job's next chunk); None when it holds none."""
    return _WORKER.get("key")


def worker_id() -> str:
    """This worker process as host:pid."""
    return f"{os.uname().nodename}:{os.getpid()}"  # (socket.gethostname's name, without the socket module)


def _renderer(job: RenderJob) -> tuple[FrameRenderer, LoadedScene, str]:
    """The worker's cached renderer for this job (built on first use, reused after)."""
    from ... import variant as variant_mod
    from .frame_renderer import FrameRenderer

    # the key's settings hash reads every file the scene names by its bytes (`content_named`):
    # the same scene text with other textures (another shot's folder) is another key
    if _WORKER.get("key") == job.key and job.cache:
        return _WORKER["renderer"], _WORKER["loaded"], _WORKER["variant"]
    # a different job (or no cache): drop the old scene first, so kernels do not bake in
    # stale object ids, then build anew
    _WORKER.clear()
    import gc

    gc.collect()
    if job.shipped is not None:
        # ship mode: the client parsed and hashed this very scene; the worker cannot see its
        # file, so there is nothing to re-read or compare (parsed once, on the client)
        loaded = job.shipped.checkout()
        scene_hash, settings_hash = job.scene_hash, job.settings_hash
    else:
        loaded = load_scene(job.scene_path, job.overrides, assets=False)  # the main process checked them
        scene_hash, settings_hash = scene_hashes(loaded)
    if (scene_hash, settings_hash) != (job.scene_hash, job.settings_hash):
        from ...errors import SceneChangedError

        raise SceneChangedError(f"{job.scene_path} changed after this render started (scene hash {scene_hash}, settings hash {settings_hash}; "
                                f"the job was planned with {job.scene_hash}, {job.settings_hash}): this worker renders nothing from it; run motion render again")
    choice = variant_mod.activate(job.variant, threads=job.threads, quiet=True)
    import mitsuba as mi

    mi.set_log_level(mi.LogLevel.Error)
    renderer = FrameRenderer(loaded)
    _WORKER.update(key=job.key, renderer=renderer, loaded=loaded, variant=choice.variant)
    return renderer, loaded, choice.variant


def _root_cause(exc: BaseException) -> str:
    """The innermost cause: drjit wraps kernel errors in 'error while performing a custom
    operation (see above)', which says nothing in a report."""
    inner = exc
    while inner.__cause__ is not None or (inner.__context__ is not None and not inner.__suppress_context__):
        inner = inner.__cause__ or inner.__context__  # type: ignore[assignment]
    message = f"{type(inner).__name__}: {inner}"
    return message if inner is exc else f"{type(exc).__name__}: {message}"


def render_frames(job: RenderJob, inputs: Sequence[BakedFrame], paths: Mapping[int, str] | None = None) -> list[FrameResult]:
    """Render and write each frame; a frame's failure is reported, not raised, so the
    others of the task still finish. `paths`: where each frame goes, as the task claimed
    and checked it (farm/task.py); without it, `frame_path`."""
    results = []
    for baked in inputs:
        results.append(_render_one(job, baked, Path(paths[baked.frame]) if paths else None))
    return results


@dataclass
class _Drawn:
    """One frame between the worker's steps: its pixels and layers, the renderer's stats,
    its field's parity (--fields) and what denoising recorded."""

    rgba: np.ndarray
    aovs: dict[str, np.ndarray]
    stats: Any
    parity: str | None
    denoise_meta: dict[str, Any]


def _draw(renderer: FrameRenderer, job: RenderJob, baked: BakedFrame) -> _Drawn:
    """Step 1, render: the frame (or with --fields its field: its own instant and shutter
    from the field timeline, only its rows) and its AOV layers."""
    parity = parity_of(baked.frame, job.fields) if job.fields else None
    rgba, aovs, stats = renderer.render_layers(baked, field=parity)
    return _Drawn(rgba, aovs, stats, parity, {})


def _denoise(drawn: _Drawn, scene: Any) -> _Drawn:
    """Step 2, denoise: right after the render, on the frame's own buffers (docs/denoise.md);
    with a temporal pass to come the frame says it is pending (render/output/temporal.py)."""
    if scene.render.denoise != "off":
        from ..output.denoise import denoise_frame

        rgba, aovs, meta = denoise_frame(drawn.rgba, drawn.aovs)
        drawn = _Drawn(rgba, aovs, drawn.stats, drawn.parity, meta)
    if scene.render.temporal != "off":
        drawn.denoise_meta["temporal"] = "pending"
    return drawn


def _header(job: RenderJob, baked: BakedFrame, loaded: LoadedScene, variant: str, drawn: _Drawn, out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """Step 3, header: the frame's identity (identity/record.py: what `--resume` and
    stale-frame checks compare), how it was rendered, and the standard attributes (capDate,
    owner, comments)."""
    from .frame_renderer import frame_seed

    scene = loaded.scene
    meta = {
        **header_attributes(job.identity(baked), settings_hash=job.settings_hash, scene_hash=job.scene_hash, look_parts=job.look_parts, files=job.files),
        "time": float(baked.time),
        "shutter_open": float(baked.shutter[0]),
        "shutter_close": float(baked.shutter[1]),
        "spp": int(scene.render.spp),
        "seed": frame_seed(scene.render.seed, baked.frame, scene.render.seed_policy),
        "seed_policy": scene.render.seed_policy,
        "motion_blur": scene.render.motion_blur,
        "variant": variant,
        "scene": scene_reference(loaded.path, out),
        "render_seconds": float(drawn.stats.render_s),
        "render_settings": json.dumps(render_settings(scene), sort_keys=True),
        **drawn.denoise_meta,
        **({"field": drawn.parity, "fieldOrder": job.fields} if drawn.parity else {}),
    }
    standard = {
        "capDate": _dt.datetime.now().strftime("%Y:%m:%d %H:%M:%S"),
        "owner": scene.output.owner or getpass.getuser(),
        "comments": scene.output.comments or f"motion render of {loaded.name}",
    }
    return meta, standard


def _write(out: Path, baked: BakedFrame, scene: Any, drawn: _Drawn, meta: dict[str, Any], standard: dict[str, Any]) -> None:
    """Step 4, write: the EXR through the write policy, its timecode from the frame number
    (1001 at 24 fps is 00:00:41:17; drop-frame at 29.97 and 59.94)."""
    fps = scene.timeline.rate
    drop = fps.denominator == 1001 and round(fps) in (30, 60)
    write_frame(
        out,
        drawn.rgba,
        meta,
        fps=Fraction(fps),
        timecode=frame_timecode(baked.frame, fps, drop_frame=drop),
        pixel_type=scene.output.pixel_type,
        compression=scene.output.compression,
        standard=standard,
        aovs=drawn.aovs or None,
    )


def _render_one(job: RenderJob, baked: BakedFrame, out: Path | None = None) -> FrameResult:
    """One frame through the worker's named steps: render, denoise, header, write (to
    `out`, the task's path for it, else `frame_path`)."""
    from ...variant import device_of

    t_setup = time.perf_counter()
    try:
        renderer, loaded, variant = _renderer(job)  # a fresh one every frame without the cache
        extra_setup = time.perf_counter() - t_setup
        drawn = _denoise(_draw(renderer, job, baked), loaded.scene)
        out = out or frame_path(job, loaded, baked.frame)
        t_write = time.perf_counter()
        meta, standard = _header(job, baked, loaded, variant, drawn, out)
        _write(out, baked, loaded.scene, drawn, meta, standard)
        stats = drawn.stats
        return FrameResult(
            frame=baked.frame,
            path=str(out),
            ok=True,
            worker=worker_id(),
            cold=stats.cold or not job.cache,
            setup_s=stats.setup_s + extra_setup,
            render_s=stats.render_s,
            write_s=time.perf_counter() - t_write,
            denoise_s=float(drawn.denoise_meta.get("denoise_seconds", 0.0)),
            kernels_compiled=stats.kernels_compiled,
            asset_cache_hits=stats.asset_cache_hits,
            variant=variant,
            device=device_of(variant),
        )
    except Exception as exc:  # reported per frame; the farm decides on retries
        from ...errors import DiskFaultError

        if isinstance(exc, DiskFaultError):  # the renderer is fine; the disk is not
            return FrameResult(frame=baked.frame, path="", ok=False, worker=worker_id(), error=str(exc), disk_fault=True)
        _WORKER.clear()  # rebuild from scratch for the next frame rather than trust this state
        return FrameResult(frame=baked.frame, path="", ok=False, worker=worker_id(), error=_root_cause(exc))
