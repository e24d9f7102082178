"""`--deliver`: every check that could fail after the last frame runs before the first
(`check_deliver`); after the last frame the deliverables are assembled and recorded in the
report (`deliver_and_record`).

A deliverable is made from the shot's frames (the timeline's first to last), whichever
frames this run rendered: `--overwrite --frames 20-23 --deliver 24p` re-renders four
frames and rebuilds the whole shot's movie with them. A format that needs every frame (a
movie) is not made while the shot lacks frames (`--deliver` says so before the first
frame; the scene's `output.deliver` leaves it out and says why); the contact sheet shows
the frames there are and names those it lacks. A deliverable of part of the shot is an
explicit choice, `--deliver-frames A-B`, named apart (`<name>_24p_20-23_v001.mov`).

Deliverables are versioned: `<name>_24p_v001.mov`, `<name>_24p_v002.mov`, the field frames
of a pulldown in `60i_v001/`. `deliver/manifest.json` says what each version was made
from (every frame's number, file and pixel digest, the frames' rate and first timecode,
and the recipe: format record, view transform, motion's version), so a rerun whose
pictures and recipe are unchanged makes no new version (a re-rendered frame of the same
pixels is the same frame, though its header differs), and one that changed makes the
next, naming what changed; a previous version is never overwritten. A frame's pixel
digest is in its EXR header (frame_output.write_exr writes it); a frame written without
one is decoded once to compute it. Each version is built in a staging folder inside
`deliver/` with the manifest's new content beside it; its outputs are then renamed into
place and the manifest last (the outputs taken back if that fails), so a failed rerun
(a full disk) leaves every version and the manifest as they were. A damaged manifest
(not JSON, wrong types, deep nesting, not a regular file) is discarded with one warning
and rebuilt; version numbers then continue from the files on disk, and an entry naming
an output outside the deliver folder is never trusted. A manifest that is a folder is
refused before the first frame. Versions are numbered v001 to v999999999; past the last,
the run says so and what to move (never a version a later run cannot read).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

from ..deliverables import FORMATS, PLAIN_VIEW
from ..errors import FrameIOError, InputFileError, UsageError
from ..farm.selection import format_frames, parse_frames
from ..timeline import format_range
from ..farm.report import write_report
from ..write_policy import confined, disk_faults, publish, publish_path, staging
from ..frame_output import disk_fault, inside
from ..identity.record import frame_pixels_digest
from ..limits import read_bounded
from ..scene.files import file_digest
from ..cache import STORES, file_stamp, package_stamps
from .request import RenderRequest

MANIFEST = "manifest.json"
MANIFEST_VERSION = 2
MAX_MANIFEST_BYTES = 64 << 20  # a manifest of thousands of versions of 10,000-frame shots
# Bumped when what a deliverable holds changes for the same frames and options (the
# movies' encoding, the view transform's defaults): old deliverables are then rebuilt.
RECIPE_VERSION = 2
MAX_VERSION = 999_999_999  # v001 .. v999999999: what a version's name holds (_VERSION)


@dataclass
class DeliverPlan:
    """The deliverables a run makes: the formats wanted (from --deliver, else the scene's
    output.deliver), those left out and why, whether --deliver asked for them, the frames
    they are made of (the shot's, or --deliver-frames) and, for a part of the shot, its
    range as named in the outputs."""

    formats: tuple[str, ...] = ()
    skipped: dict[str, str] = field(default_factory=dict)
    explicit: bool = False
    frames: tuple[int, ...] = ()
    part: str | None = None

    def __bool__(self) -> bool:
        return bool(self.formats)

    def key(self, fmt: str) -> str:
        """The manifest's key of format `fmt` of this plan: '24p', or '24p@20-23' for a part."""
        return fmt if self.part is None else f"{fmt}@{self.part}"

    def tag(self, fmt: str) -> str:
        """What names the outputs (before the version): '24p', or '24p_20-23' for a part."""
        return fmt if self.part is None else f"{fmt}_{self.part.replace(',', '+')}"


def deliver_view(req: RenderRequest) -> Any:
    """The deliverables' `ViewTransform` from the request's exposure and OCIO options."""
    from ..telecine.movie import ViewTransform

    view = req.deliver_view
    return ViewTransform(view.exposure, view.ocio_config, view.ocio_display, view.ocio_view)


def _view_entry(req: RenderRequest) -> Path | None:
    """Where the description of the request's view transform is kept (cache.STORES["probes"]):
    keyed by the view's options, the config file they name (path, size, time), the installed
    OpenColorIO's files and the code that describes it (telecine/movie.py). None for a config
    that cannot be stamped (absent: building the view says why)."""
    view = req.deliver_view
    parts = [repr(float(view.exposure)), repr(view.ocio_config), repr(view.ocio_display), repr(view.ocio_view),
             file_stamp(Path(__file__).resolve().parents[1] / "telecine" / "movie.py"), *package_stamps("PyOpenColorIO")]
    config = view.ocio_config
    if config is not None and not str(config).startswith("ocio://") and str(config).strip().lower() not in PLAIN_VIEW:
        stamp = file_stamp(os.path.realpath(config))
        if stamp.endswith(":absent"):
            return None
        parts.append(stamp)
    store = STORES["probes"]
    return store.path(store.key(*parts), stem="view", suffix=".txt")


def view_description(req: RenderRequest) -> str:
    """The description of the request's view transform, which a deliverable's recipe
    records: kept from the last run that built the same view (`_view_entry`), else the view
    built now (OpenColorIO loaded and the config checked), so a rerun whose deliverables are
    up to date loads neither OpenColorIO nor NumPy. check_deliver asks first in every run
    that delivers, so the view it builds is the one kept."""
    entry = _view_entry(req)
    data = STORES["probes"].read(entry, 4096) if entry is not None else None
    if data:
        try:
            return data.decode()
        except UnicodeDecodeError:
            pass
    description = str(deliver_view(req).description)
    if entry is not None:
        STORES["probes"].put(entry, description.encode(), best_effort=True, doing="keeping the view transform's description")
    return description


def shot_frames(loaded: Any) -> list[int]:
    """The shot's frames: the timeline's first to last."""
    tl = loaded.scene.timeline
    return list(range(int(tl.first), int(tl.last) + 1))


def deliver_plan(req: RenderRequest, loaded: Any, frames: list[int]) -> DeliverPlan:
    """Which deliverables this run makes, of which frames. `--deliver` is strict (a
    deliverable that cannot be made is an error before the first frame: check_deliver);
    the scene's `output.deliver` is what a full render of the shot makes, and a run that
    leaves the shot incomplete (a preset's spread of frames, a shard) makes what it can and
    says what it left out. `--deliver none` makes nothing."""
    from ..deliverables import parse_formats

    if req.deliver is not None and req.deliver.strip().lower() == "none":
        return DeliverPlan()
    explicit = bool(req.deliver)
    formats = parse_formats(req.deliver) if req.deliver else tuple(getattr(loaded.scene.output, "deliver", ()) or ())
    if not formats:
        if req.deliver_frames:
            raise UsageError(f"--deliver-frames {req.deliver_frames}: no deliverables asked for (--deliver, or the scene's output.deliver)")
        return DeliverPlan()
    shot = shot_frames(loaded)
    part: str | None = None
    if req.deliver_frames:
        try:
            chosen = parse_frames(req.deliver_frames, shot[0], shot[-1])
        except UsageError as exc:  # (the grammar's errors name --frames: this is --deliver-frames)
            raise UsageError("--deliver-frames: " + str(exc).removeprefix("--frames: ")) from None
        if chosen != shot:  # the whole shot named as a range is the shot
            part = format_frames(chosen)
        shot = chosen
    if req.shard and not explicit:
        return DeliverPlan((), {f: "a shard makes no deliverables: assemble after every shard with --check --deliver" for f in formats}, frames=tuple(shot))
    if req.check and not explicit:  # a check writes nothing but its report
        why = "--check makes no deliverables unless asked: --check --deliver"
        for f in formats:
            logging.getLogger("motion").info(f"  {f}: not made: {why} (the scene's output.deliver)")
        return DeliverPlan((), {f: why for f in formats}, frames=tuple(shot))
    return DeliverPlan(formats, {}, explicit, tuple(shot), part)


NO_PYAV = "movies need PyAV (pip install av), which is not installed here"


def _installed(module: str) -> bool:
    """Whether `module` can be found (located, not imported)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def check_deliver(req: RenderRequest, loaded: Any, plan: DeliverPlan, frames: list[int], out_dir: Path,
                  path_of: Callable[[int], Path]) -> DeliverPlan:
    """What `--deliver` would find wrong after the last frame, found before the first:
    format names, the view transform (OCIO config, display, view), interlaced formats on an
    odd height, the movie encoders, a deliver folder that is a file or a link out of the
    output folder, and the frames a deliverable needs that neither are on disk nor are
    rendered by this run (`frames`). Returns the plan without the scene-declared formats
    that cannot be made (each with why). The view and the encoders are checked once per
    config and install (view_description, check_encoders), so a rerun loads neither
    OpenColorIO nor FFmpeg. Nothing is created here: a run that fails or renders nothing
    leaves no empty deliver folder."""
    view_description(req)  # a bad OCIO config, display or view (the view is built unless this one was built before)
    records = [FORMATS[f] for f in plan.formats]
    height = loaded.scene.render.resolution[1]
    interlaced = [r.name for r in records if r.interlaced]
    if interlaced and height % 2:
        raise UsageError(f"--deliver {','.join(interlaced)}: the render is {height} rows high; interlaced fields need an even height (--resolution)")
    movies = [r for r in records if r.codec is not None]
    if movies and not _installed("av"):  # a dependency, but a farm node or a container may have been built without it
        why = NO_PYAV
        if plan.explicit:
            raise UsageError(f"--deliver {','.join(r.name for r in movies)}: {why}; install it, or ask only for the contact sheet (--deliver contact)")
        # the scene's own output.deliver: made without its movies, each said why
        plan = replace(plan, formats=tuple(f for f in plan.formats if FORMATS[f].codec is None), skipped={**plan.skipped, **{r.name: why for r in movies}})
        records = [r for r in records if r.codec is None]
    check_encoders(req, plan)
    folder = out_dir / "deliver"
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise UsageError(f"--deliver: {folder} is {'a link' if folder.is_symlink() else 'a file'}; deliverables are written only into a real folder inside the output folder")
    check_manifest_path(folder)
    gaps = [b for a, b in zip(plan.frames, plan.frames[1:]) if b != a + 1]
    if gaps and plan.part is not None and any(r.gapless for r in records):
        raise UsageError(f"--deliver-frames {plan.part}: a movie needs a gapless run of frames (A-B)")
    rendered = set(frames)
    lacking = [f for f in plan.frames if f not in rendered and not os.path.exists(path_of(f))]
    if not lacking:
        return plan
    what = f"frames {format_frames(list(plan.frames))}" if plan.part else f"the shot (frames {format_frames(list(plan.frames))})"
    why = f"{what} lacks frames {format_frames(lacking)} (neither on disk nor in this run)"
    blocked = [r.name for r in records if r.gapless]
    if blocked and plan.explicit:
        run = format_range(frames[0], frames[-1]) if frames and frames == list(range(frames[0], frames[-1] + 1)) else "A-B"
        hint = "" if plan.part else f"; render them too, or make a deliverable of part of the shot with --deliver-frames {run}"
        raise UsageError(f"--deliver {','.join(blocked)}: a movie is made from a gapless run of frames, the whole shot: {why}{hint}")
    return replace(plan, formats=tuple(f for f in plan.formats if f not in blocked),
                   skipped={**plan.skipped, **{f: f"{why}: not a gapless run" for f in blocked}})


def check_encoders(req: RenderRequest, plan: DeliverPlan) -> None:
    """Each movie of the plan has its encoder in the installed PyAV/FFmpeg: probed once per
    build of PyAV (its files' stamps, cache.STORES["probes"]), so a rerun does not load
    FFmpeg to learn it again."""
    movies = [FORMATS[f] for f in plan.formats if FORMATS[f].codec is not None]
    if not movies:
        return
    store = STORES["probes"]
    entry = store.path(store.key("encoders", *sorted({str(r.codec) for r in movies}), *package_stamps("av")), stem="encoders", suffix=".txt")
    if store.read(entry, 64) == b"ok":
        return
    try:
        import av
    except ImportError:  # found but not loadable (a library of FFmpeg's missing)
        raise UsageError(f"--deliver {','.join(r.name for r in movies)}: {NO_PYAV}; install it, or ask only for the contact sheet (--deliver contact)") from None
    from ..telecine.movie import CODECS

    for r in movies:
        try:
            av.codec.Codec(CODECS[r.codec].encoder, "w")
        except Exception:  # PyAV raises its own UnknownCodecError
            raise UsageError(f"--deliver {r.name}: this build of PyAV/FFmpeg has no {CODECS[r.codec].encoder} encoder") from None
    store.put(entry, b"ok", best_effort=True, doing="keeping the movie encoders' probe")


# --- what a deliverable was made from -------------------------------------------------------


def frame_digests(paths: list[Path], known: Mapping[str, Any]) -> list[str]:
    """The pixel digest of each frame (identity/record.py `frame_pixels_digest`: from its header,
    or decoded for a frame written without one). A file whose name, size and modification
    time match the manifest's record keeps its recorded digest (as git's index does), so
    an unchanged folder is not read again on every rerun."""
    out = []
    for p in paths:
        st = p.stat()
        rec = known.get(p.name)
        if isinstance(rec, dict) and rec.get("size") == st.st_size and rec.get("mtime_ns") == st.st_mtime_ns and _digest(rec.get("pixels")):
            out.append(rec["pixels"])
            continue
        try:
            out.append(frame_pixels_digest(p))
        except FrameIOError as exc:
            raise UsageError(f"--deliver: {exc}") from None
    return out


def check_manifest_path(folder: Path) -> None:
    """A manifest that is a folder cannot be replaced by the new one: refused (before the
    first frame, and again before anything is published), never a version left
    unrecorded. A link, a FIFO or a damaged file is replaced (read_manifest warns)."""
    path = folder / MANIFEST
    if path.is_dir() and not path.is_symlink():
        raise UsageError(f"--deliver: {path} is a folder; the deliverables' manifest is a file there: move the folder away")


_VERSION = re.compile(r"^v(\d{3,9})$")
_SHA = re.compile(r"^[0-9a-f]{64}$")


def _plain_name(name: Any) -> bool:
    """A single file or folder name (no separator, no `..`, no NUL): what an output entry
    may name inside the deliver folder."""
    return (isinstance(name, str) and 0 < len(name) <= 255 and name not in (".", "..") and "/" not in name
            and "\\" not in name and "\0" not in name)


def _int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _digest(v: Any) -> bool:
    return isinstance(v, str) and _SHA.match(v) is not None


def _version_ok(v: Any) -> bool:
    """One version's record has the shape we write (anything else: the manifest is damaged)."""
    if not isinstance(v, dict) or not isinstance(v.get("made_from"), str) or not isinstance(v.get("recipe"), dict):
        return False
    outs, files = v.get("outputs"), v.get("frame_files")
    if not isinstance(outs, list) or not all(isinstance(o, dict) and _plain_name(o.get("name")) and (o.get("size") is None or _int(o.get("size"))) for o in outs):
        return False
    return isinstance(files, dict) and all(
        isinstance(k, str) and isinstance(r, dict) and _plain_name(r.get("name")) and _int(r.get("size")) and _int(r.get("mtime_ns"))
        and (_digest(r.get("pixels")) or _digest(r.get("sha256"))) for k, r in files.items())  # (sha256: a whole file, before pixel digests)


def _manifest_problem(data: Any) -> str | None:
    """Why a parsed manifest is not one we wrote (wrong types anywhere), or None."""
    if not isinstance(data, dict) or data.get("version") != MANIFEST_VERSION or not isinstance(data.get("deliverables"), dict):
        return "not a manifest of this version"
    for key, entry in data["deliverables"].items():
        if not isinstance(entry, dict) or not isinstance(entry.get("versions"), dict):
            return f"entry {key!r} is not a record of versions"
        for name, v in entry["versions"].items():
            if not (isinstance(name, str) and _VERSION.match(name)) or not _version_ok(v):
                return f"version {name!r} of {key!r} is not a record we write"
    return None


def read_manifest(folder: Path, warn: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The deliver folder's manifest, or an empty one when it is absent. A damaged one (not
    a regular file, over MAX_MANIFEST_BYTES, not JSON, nested too deep, wrong types) is
    discarded with one warning line: it is rebuilt from the versions made from now on, and
    version numbers continue from the files on disk (next_version)."""
    empty: dict[str, Any] = {"version": MANIFEST_VERSION, "deliverables": {}}
    path = folder / MANIFEST
    if not os.path.lexists(path):
        return empty
    data: Any = None
    try:
        data = json.loads(read_bounded(path, MAX_MANIFEST_BYTES, "the deliverables' manifest"))
        problem = _manifest_problem(data)
    except InputFileError as exc:
        problem = exc.reason
    except (ValueError, RecursionError) as exc:
        problem = f"not JSON ({type(exc).__name__})"
    if problem is None:
        return data  # type: ignore[no-any-return]
    legacy = isinstance(data, dict) and isinstance(data.get("formats"), dict) and "deliverables" not in data
    if not legacy:
        (warn or logging.getLogger("motion").warning)(f"motion: warning: {path}: damaged ({problem}); discarded, rebuilt from the deliverables made from now on")
    return empty  # (a manifest of motion before versions: its unversioned files stay, never overwritten)


def recipe(fmt: str, view: Any) -> dict[str, Any]:
    """What a deliverable is made with besides its frames: the format's record, the view
    transform, the recipe's and motion's versions."""
    from .. import VERSION

    return {"format": fmt, **FORMATS[fmt].recipe(), "view": getattr(view, "description", view),
            "recipe_version": RECIPE_VERSION, "motion": VERSION}


def _last_version(entry: Mapping[str, Any]) -> tuple[str | None, dict[str, Any] | None]:
    """A deliverable's manifest entry's last version: (its name, its record), or (None, None)."""
    name = max(entry["versions"], key=lambda v: int(v[1:]), default=None)
    return name, (entry["versions"][name] if name else None)


def _kept_as_made(fmt: str, last: Mapping[str, Any], view: Any, folder: Path) -> bool:
    """Whether version `last` of `fmt` was made with this recipe (`view`: the view transform
    or its description) and its outputs are still there: with its frames unchanged, it is up
    to date."""
    return last["recipe"] == recipe(fmt, view) and _outputs_present(last, folder)


def _outputs_present(version: Mapping[str, Any], folder: Path) -> bool:
    """Every output a version lists is still there, inside the deliver folder (a link out
    of it is not trusted), at its recorded size."""
    outs = version.get("outputs") or []
    for o in outs:
        p = folder / o["name"]
        if not p.exists() or not confined(folder, p) or (p.is_file() and p.stat().st_size != o.get("size")):
            return False
    return bool(outs)


def next_version(folder: Path, prefix: str, tag: str, entry: Mapping[str, Any]) -> int:
    """The next version number of a deliverable: past every version the manifest records
    and every file or folder of that name on disk (so a discarded manifest never leads to
    an overwrite)."""
    recorded = max((int(m.group(1)) for v in entry.get("versions", {}) if (m := _VERSION.match(v))), default=0)
    names = re.compile(rf"^(?:{re.escape(prefix)}_)?{re.escape(tag)}_v(\d{{3,9}})(?:\.[A-Za-z0-9]+)?$")
    on_disk = [(int(m.group(1)), p.name) for p in folder.iterdir() if (m := names.match(p.name))] if folder.is_dir() else []
    last = max([recorded, *(n for n, _ in on_disk)])
    if last >= MAX_VERSION:  # a name holds 9 digits: v1000000000 would be a version no later run reads
        where = (f"{folder / MANIFEST} records v{recorded:03d}" if recorded >= MAX_VERSION
                 else f"{folder / max(on_disk)[1]} is there")
        raise UsageError(f"--deliver {tag}: {where}, the last version a name holds (v001 to v{MAX_VERSION}); "
                         f"move the {tag} versions out of {folder} (and their entry out of {MANIFEST}) to number them from v001 again")
    return last + 1


def movie_rate(path: Path, interlaced: bool = False) -> str | None:
    """The rate a movie plays at, as read back from the file ('23.976 fps (24000/1001)'),
    for the log and the manifest: a "24p" deliverable plays at the telecine's 23.976."""
    if path.suffix.lower() not in (".mov", ".mp4"):
        return None
    import av

    from ..timeline import rate_label

    try:
        with av.open(str(path)) as c:
            stream = c.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate
    except Exception:  # an unreadable movie is reported by whoever plays it; the label is a courtesy
        return None
    return (rate_label(rate) + (" interlaced, 2 fields a frame" if interlaced else "")) if rate else None


def _changed(before: Mapping[str, Any] | None, files: Mapping[str, Any], timing: Mapping[str, Any], same_recipe: bool) -> str:
    """Why a new version is made, from the last version's record and these frames:
    'frames 20-23 changed', 'frames 30-31 gone', 'the frames' rate or timecode changed',
    'the recipe changed', or that its outputs are gone. Only a change that is there."""
    if not before:
        return ""
    old = before.get("frame_files", {})
    if old and not any(_digest(r.get("pixels")) for r in old.values() if isinstance(r, dict)):
        return "frame files rewritten or changed; an earlier motion recorded whole files, not pixels"
    diff = [int(n) for n, r in files.items() if (old.get(n) or {}).get("pixels") != r["pixels"]]
    gone = [int(n) for n in old if n not in files and n.lstrip("-").isdigit()]
    parts = ([f"frames {format_frames(sorted(diff))} changed"] if diff else []) + ([f"frames {format_frames(sorted(gone))} gone"] if gone else [])
    if "timing" in before and before["timing"] != dict(timing):
        parts.append("the frames' rate or timecode changed")
    if not same_recipe:
        parts.append("the recipe changed")
    return "; ".join(parts) or "its outputs are gone"


def _since(why: str, last_name: str | None) -> str:
    """'frames 4-7 changed since v001'; a reason with a clause after ';' keeps it last."""
    head, sep, tail = why.partition("; an earlier")
    return f"{head} since {last_name}" + (f"{sep}{tail}" if sep else "")


def _outputs_of(done: list[Path], staged: Path) -> list[str]:
    """The top-level names (files, or a pulldown's folder) of what a maker wrote in `staged`."""
    names: list[str] = []
    for p in done:
        top = Path(p).relative_to(staged).parts[0]
        if top not in names:
            names.append(top)
    return names


def _publish(staged: Path, names: list[str], manifest_tmp: Path, folder: Path) -> None:
    """Move a version's staged outputs into `folder`, then the manifest that records them
    (its new content already written whole in `manifest_tmp`): renames only, the manifest
    last. If any step fails, the outputs already moved are taken back (they are new names:
    nothing of an earlier version is touched), so the folder and its manifest stay as they
    were."""
    clash = [n for n in names if os.path.lexists(folder / n)]
    if clash:  # (another run made this version meanwhile): never overwrite one
        raise UsageError(f"--deliver: {folder / clash[0]} appeared while it was being made; run again for the next version")
    check_manifest_path(folder)
    moved: list[Path] = []
    try:
        with disk_faults("publishing a deliverable in", folder):
            for name in names:
                publish_path(staged / name, folder / name)
                moved.append(folder / name)
            publish(manifest_tmp, folder / MANIFEST)
    except BaseException:
        for path in moved:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        raise


def _deliver_folder(out_dir: Path) -> Path:
    """The deliver folder inside `out_dir`, created: a real folder, never a link out of it."""
    folder = out_dir / "deliver"
    if folder.is_symlink() or not inside(out_dir, folder):
        raise UsageError(f"--deliver: {folder} is a link; deliverables are written only into a real folder inside the output folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fault = disk_fault(exc, "creating", folder)
        if fault is not None:
            raise fault from None
        raise UsageError(f"--deliver: cannot create {folder}: {exc.strerror}") from None
    return folder


def _frames_there(out_dir: Path, plan: DeliverPlan, frame_paths: Mapping[int, Path]) -> tuple[dict[int, Path], list[int]]:
    """The plan's frames on disk (number -> file) and the frames it lacks (an error for a
    format that needs every frame)."""
    there = {n: Path(frame_paths[n]) for n in plan.frames if n in frame_paths and Path(frame_paths[n]).is_file()}
    lacking = [n for n in plan.frames if n not in there]
    if lacking and any(FORMATS[f].gapless for f in plan.formats):
        raise UsageError(f"--deliver: frames {format_frames(lacking)} of {format_frames(list(plan.frames))} are not in {out_dir}")
    if not there:
        raise UsageError(f"--deliver: none of frames {format_frames(list(plan.frames))} is in {out_dir}")
    return there, lacking


def _shot_sequence(out_dir: Path, plan: DeliverPlan, there: dict[int, Path], prefix: str) -> Any:
    """The validated sequence of the frames `there`."""
    from ..telecine.sequence import sequence_of

    try:
        return sequence_of(there, prefix, directory=out_dir, require_even_height=any(FORMATS[f].interlaced for f in plan.formats))
    except FrameIOError as exc:
        raise UsageError(f"--deliver: {exc}") from None


def _as_recorded(req: RenderRequest, plan: DeliverPlan, folder: Path, manifest: Mapping[str, Any], there: Mapping[int, Path],
                 lacking: list[int]) -> dict[str, str] | None:
    """{format: its last version} when every deliverable of the plan is up to date without
    opening a frame: its last version was made from exactly these files, each at the name,
    size and modification time it records (as git's index trusts a file; its pixels, rate
    and timecode are then those recorded), lacking the same frames, with this recipe (the
    view's kept description), its outputs there. None when any is not (the frames are then
    read: deliver_and_record)."""
    current: dict[str, str] = {}
    description: str | None = None
    for fmt in plan.formats:
        last_name, last = _last_version(manifest["deliverables"].get(plan.key(fmt)) or {"versions": {}})
        if last is None or last.get("lacks") != (format_frames(lacking) or None):
            return None
        files = last["frame_files"]
        if set(files) != {str(n) for n in there}:
            return None
        for n, path in there.items():
            rec, st = files[str(n)], path.stat()
            if rec["name"] != path.name or rec["size"] != st.st_size or rec["mtime_ns"] != st.st_mtime_ns or not _digest(rec.get("pixels")):
                return None
        description = description if description is not None else view_description(req)
        if not _kept_as_made(fmt, last, description, folder):
            return None
        current[fmt] = last_name  # type: ignore[assignment]
    return current


def _say_up_to_date(fmt: str, name: str, numbers: list[int], lacking: list[int], folder: Path, outputs: list[str], say: Callable[[str], None]) -> None:
    """'  24p: up to date (v002, frames 1-48 unchanged): PATH'."""
    lacks = f" (lacks frames {format_frames(lacking)})" if lacking else ""
    say(f"  {fmt}: up to date ({name}, frames {format_frames(numbers)} unchanged{lacks}): " + ", ".join(str(folder / n) for n in outputs))


@dataclass(frozen=True)
class _Made:
    """What the deliverables of one run are made from: the sequence, its frames' records
    (number -> name, size, time, pixel digest), the frames' rate and first timecode, their
    digest, the frames lacking, the view and the frames as viewed."""

    seq: Any
    frame_files: dict[str, dict[str, Any]]
    timing: dict[str, Any]
    made_from: str
    lacking: list[int]
    view: Any
    shared: Any = None  # the frames as viewed, shared by the run's deliverables (each viewed once)

    @property
    def lacks(self) -> str:
        """' (lacks frames 3-5)' for a log line, or ''."""
        return f" (lacks frames {format_frames(self.lacking)})" if self.lacking else ""


def _version_record(fmt: str, made: _Made, staged: Path, names: list[str]) -> dict[str, Any]:
    """The manifest's record of a version whose outputs `names` are staged in `staged`."""
    interlaced = FORMATS[fmt].interlaced
    outputs = [{"name": n, "size": (staged / n).stat().st_size if (staged / n).is_file() else None,
                "rate": movie_rate(staged / n, interlaced)} for n in names]
    return {"frames": format_frames(list(made.seq.numbers)), "lacks": format_frames(made.lacking) or None, "made_from": made.made_from,
            "timing": made.timing, "recipe": recipe(fmt, made.view), "outputs": outputs, "frame_files": made.frame_files,
            "made_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def _new_version(fmt: str, plan: DeliverPlan, made: _Made, folder: Path, prefix: str, manifest: dict[str, Any],
                 entry: dict[str, Any], last_name: str | None, say: Callable[[str], None]) -> tuple[str, list[str]]:
    """Make the next version of `fmt` in a staging folder, with the manifest that records
    it written there too; then publish both (_publish: outputs, then the manifest) and say
    where it is. Its name and output names."""
    from ..telecine.deliver import deliver

    last = entry["versions"].get(last_name) if last_name else None
    name = f"v{next_version(folder, prefix, plan.tag(fmt), entry):03d}"
    with staging(folder, f"making the {fmt} deliverable in", prefix=f".staging-{fmt}-") as staged:
        done = deliver(made.seq.directory, staged, (fmt,), view=made.view, sequence=made.seq, tags={fmt: f"{plan.tag(fmt)}_{name}"}, shared=made.shared)[fmt]
        names = _outputs_of(done, staged)
        version = _version_record(fmt, made, staged, names)
        updated = {**manifest, "deliverables": {**manifest["deliverables"], plan.key(fmt): {
            **entry, "versions": {**entry["versions"], name: version}, "format": fmt, "part": plan.part, "latest": name}}}
        manifest_tmp = staged / f".{MANIFEST}.new"
        with disk_faults("writing the deliverables' manifest", folder / MANIFEST):
            with open(manifest_tmp, "wb") as fh:
                fh.write((json.dumps(updated, indent=2) + "\n").encode())
                fh.flush()
                os.fsync(fh.fileno())
        _publish(staged, names, manifest_tmp, folder)
    manifest["deliverables"] = updated["deliverables"]  # (what is on disk now)
    why = _changed(last, made.frame_files, made.timing, last is not None and last.get("recipe") == recipe(fmt, made.view)) if last is not None else ""
    for o in version["outputs"]:
        p = folder / o["name"]
        if p.is_dir():
            say(f"  {fmt}: {name}: {len(list(p.glob('*.exr')))} frames in {p}")
        else:
            say(f"  {fmt}: {name}: {p}" + (f" ({o['rate']})" if o["rate"] else "") + made.lacks + (f" ({_since(why, last_name)})" if why else ""))
    return name, names


def _same_frames(last: Mapping[str, Any], made: _Made) -> bool:
    """Whether version `last` was made from these frames: its pixel-keyed digest; for a
    version an earlier motion recorded by whole files (SHA-256 of each file), those files
    unchanged (the old digest, from the file's size and time when they match its record),
    so upgrading motion makes no version of an unchanged shot."""
    if last["made_from"] == made.made_from:
        return True
    old = last.get("frame_files") or {}
    if not old or any(_digest(r.get("pixels")) for r in old.values()) or set(old) != set(made.frame_files):
        return False
    by_name = {r["name"]: r for r in old.values()}
    digests = []
    for p in made.seq.paths:
        st, rec = p.stat(), by_name.get(p.name)
        known = isinstance(rec, dict) and rec.get("size") == st.st_size and rec.get("mtime_ns") == st.st_mtime_ns
        digests.append(rec["sha256"] if known else file_digest(p, memo=False))  # type: ignore[index]
    return last["made_from"] == hashlib.sha256(json.dumps([[n, d] for n, d in zip(made.seq.numbers, digests)]).encode()).hexdigest()


def _one_format(fmt: str, plan: DeliverPlan, made: _Made, folder: Path, prefix: str, manifest: dict[str, Any],
                say: Callable[[str], None]) -> tuple[str, str, list[str]]:
    """The deliverable `fmt`: its last version when made from these pictures with this
    recipe and still there, else a new version; (status, version, output names)."""
    entry = manifest["deliverables"].get(plan.key(fmt)) or {"versions": {}}
    last_name, last = _last_version(entry)
    if last is not None and _same_frames(last, made) and _kept_as_made(fmt, last, made.view, folder):
        names = [o["name"] for o in last["outputs"]]
        _say_up_to_date(fmt, last_name, list(made.seq.numbers), made.lacking, folder, names, say)  # type: ignore[arg-type]
        return "up to date", last_name, names  # type: ignore[return-value]
    name, names = _new_version(fmt, plan, made, folder, prefix, manifest, entry, last_name, say)
    return "made", name, names


def _made_of(req: RenderRequest, plan: DeliverPlan, out_dir: Path, there: dict[int, Path], lacking: list[int], prefix: str,
             manifest: Mapping[str, Any]) -> _Made:
    """What this run's deliverables are made from: the frames read (headers, and the pixels
    of a frame without a digest), their rate and first timecode, and the view."""
    view = deliver_view(req)
    seq = _shot_sequence(out_dir, plan, there, prefix)
    known = {r["name"]: r for e in manifest["deliverables"].values() for v in e["versions"].values() for r in v["frame_files"].values()}
    numbers = list(seq.numbers)
    digests = frame_digests(list(seq.paths), known)
    frame_files = {str(n): {"name": p.name, "size": p.stat().st_size, "mtime_ns": p.stat().st_mtime_ns, "pixels": d}
                   for n, p, d in zip(numbers, seq.paths, digests)}
    from ..telecine.movie import ViewedFrames, first_timecode

    # what a deliverable takes from the frames besides their pixels: the rate and the first timecode
    timing = {"fps": str(seq.fps) if seq.fps is not None else None, "timecode": first_timecode(seq)}
    made_from = hashlib.sha256(json.dumps({"pixels": [[n, d] for n, d in zip(numbers, digests)], "timing": timing}).encode()).hexdigest()
    return _Made(seq, frame_files, timing, made_from, lacking, view, ViewedFrames(seq, view))


def deliver_and_record(req: RenderRequest, out_dir: Path, plan: DeliverPlan, frame_paths: Mapping[int, Path], prefix: str,
                       report: dict[str, Any], report_path: Path | None, say: Callable[[str], None]) -> dict[str, Any]:
    """Assemble the plan's deliverables from `frame_paths` (frame number -> file, the
    numbers carried, never parsed back from the names): a new version of each whose
    frames or recipe changed since its last version, none of one unchanged; print where
    each one is and record them in the report (rewritten in place) and in
    deliver/manifest.json."""
    folder = _deliver_folder(out_dir)
    check_manifest_path(folder)
    there, lacking = _frames_there(out_dir, plan, frame_paths)
    manifest = read_manifest(folder)
    numbers = sorted(there)
    status: dict[str, str] = {}
    versions: dict[str, str] = {}
    outputs: dict[str, list[str]] = {}
    current = _as_recorded(req, plan, folder, manifest, there, lacking)
    if current is not None:  # every one up to date, no frame opened
        for fmt, name in current.items():
            status[fmt], versions[fmt] = "up to date", name
            outputs[fmt] = [o["name"] for o in manifest["deliverables"][plan.key(fmt)]["versions"][name]["outputs"]]
            _say_up_to_date(fmt, name, numbers, lacking, folder, outputs[fmt], say)
    else:
        made = _made_of(req, plan, out_dir, there, lacking, prefix, manifest)
        for fmt in plan.formats:
            status[fmt], versions[fmt], outputs[fmt] = _one_format(fmt, plan, made, folder, prefix, manifest, say)
    record: dict[str, Any] = {}
    for fmt in plan.formats:
        names = outputs[fmt]
        rates = {o.get("name"): o.get("rate") for o in manifest["deliverables"][plan.key(fmt)]["versions"][versions[fmt]]["outputs"]}
        for n in names:
            p = folder / n
            if p.is_dir():
                record[f"{fmt}_frames"] = [str(p)]
            else:
                record.setdefault(fmt, []).append(str(p))
                if rates.get(n):  # a movie's rate as read back: '23.976 fps (24000/1001)'
                    record.setdefault("rates", {})[str(p)] = rates[n]
    record.update(status=status, versions=versions, frames=format_frames(numbers))
    if lacking:
        record["lacks"] = format_frames(lacking)
    if plan.part:
        record["part"] = plan.part
    report["deliverables"] = record
    if report_path is not None:  # None: no folder would take the report (a disk fault)
        write_report(report, report_path)
    return record
