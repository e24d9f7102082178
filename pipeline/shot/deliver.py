"""`--deliver`: every check that could fail after the last frame runs before the first
(`check_deliver`); after the last frame the deliverables are assembled and recorded in the
report (`deliver_and_record`).

A deliverable records what it was made from (`deliver/manifest.json`: the frame numbers,
a SHA-256 of each frame file and the recipe: format, view transform, cadence), so the same
command run twice rebuilds nothing, and a rerun rebuilds only the deliverables whose frames
or recipe changed (`--overwrite` rebuilds them all). Each format is built in a staging folder
inside `deliver/` and published whole (movies and sheets by an atomic rename, the 60i/50i
field folders by swapping the folder), so a failed rerun leaves every deliverable as it was,
with the manifest still describing it.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from ..errors import FrameIOError, UsageError
from ..farm.frames import format_frames
from ..farm.report import write_report
from ..files import publish_path, staging
from ..frame_output import disk_fault, inside, write_atomic
from .request import RenderRequest

MANIFEST = "manifest.json"
# Bumped when what a deliverable holds changes for the same frames and options (the
# movies' encoding, the view transform's defaults): old deliverables are then rebuilt.
RECIPE_VERSION = 1
# Formats that are a gapless sequence (a movie); the contact sheet is a glance and takes any frames.
SEQUENCE_FORMATS = ("24p", "60i", "50i", "review")


@dataclass
class DeliverPlan:
    """The deliverables a run makes: the formats wanted (from --deliver, else the scene's
    output.deliver), those left out and why, and whether --deliver asked for them."""

    formats: tuple[str, ...] = ()
    skipped: dict[str, str] = field(default_factory=dict)
    explicit: bool = False

    def __bool__(self) -> bool:
        return bool(self.formats)


def deliver_view(req: RenderRequest) -> Any:
    """The deliverables' `ViewTransform` from the request's exposure and OCIO options."""
    from ..telecine.movie import ViewTransform

    return ViewTransform(**{k: v for k, v in req.deliver_view.items() if v is not None})


def deliver_plan(req: RenderRequest, loaded: Any, frames: list[int]) -> DeliverPlan:
    """Which deliverables this run makes. `--deliver` is strict: a selection with gaps or a
    shard is an error. The scene's `output.deliver` is what a full render of the shot makes:
    a run that covers only part of it (a preset's spread of frames, a shard) makes what it
    can and says what it left out (`--deliver none` makes nothing)."""
    from ..telecine.deliver import parse_formats

    if req.deliver is not None and req.deliver.strip().lower() == "none":
        return DeliverPlan()
    if req.deliver:
        return DeliverPlan(parse_formats(req.deliver), explicit=True)
    declared = tuple(getattr(loaded.scene.output, "deliver", ()) or ())
    if not declared:
        return DeliverPlan()
    if req.shard:
        return DeliverPlan((), {f: "a shard makes no deliverables: assemble after every shard with --check" for f in declared})
    gaps = any(b != a + 1 for a, b in zip(frames, frames[1:]))
    keep = tuple(f for f in declared if not (gaps and f in SEQUENCE_FORMATS))
    skipped = {f: f"frames {format_frames(frames)} are not a gapless run" for f in declared if f not in keep}
    return DeliverPlan(keep, skipped)


def check_deliver(req: RenderRequest, loaded: Any, frames: list[int], out_dir: Path, wanted: tuple[str, ...]) -> None:
    """What `--deliver` would find wrong after the last frame, found before the first:
    format names, the view transform (OCIO config, display, view), interlaced formats on an
    odd height, negative frames, a selection with gaps (the telecine needs a gapless sequence), the movie
    encoders, a deliver folder that is a file or a link out of the output folder. Nothing
    is created here: a run that fails or renders nothing leaves no empty deliver folder."""
    from ..telecine.movie import CODECS

    deliver_view(req)  # a bad OCIO config, display or view
    height = loaded.scene.render.resolution[1]
    interlaced = [f for f in wanted if f in ("60i", "50i")]
    if interlaced and height % 2:
        raise UsageError(f"--deliver {','.join(interlaced)}: the render is {height} rows high; interlaced fields need an even height (--resolution)")
    negative = [f for f in frames if f < 0]
    if negative:  # the sequence reader of every deliverable numbers frames from 0 (it rendered them all, then refused)
        raise UsageError(
            f"--deliver {','.join(wanted)}: frames {format_frames(negative)} are negative; deliverables are made from frames numbered from 0 "
            f"(render them without --deliver, or start the timeline at 0)"
        )
    gaps = [b for a, b in zip(frames, frames[1:]) if b != a + 1]
    if gaps and any(f in SEQUENCE_FORMATS for f in wanted):
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
    folder = out_dir / "deliver"
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise UsageError(f"--deliver: {folder} is {'a link' if folder.is_symlink() else 'a file'}; deliverables are written only into a real folder inside the output folder")


# --- what a deliverable was made from -------------------------------------------------------


def frame_digests(paths: list[Path], known: dict[str, Any]) -> list[str]:
    """SHA-256 of each frame file. A file whose name, size and modification time match the
    manifest's record keeps its recorded digest (as git's index does), so an unchanged
    folder of 1080p frames is not read again on every rerun."""
    out = []
    for p in paths:
        st = p.stat()
        rec = known.get(p.name)
        if isinstance(rec, dict) and rec.get("size") == st.st_size and rec.get("mtime_ns") == st.st_mtime_ns and isinstance(rec.get("sha256"), str):
            out.append(rec["sha256"])
            continue
        h = hashlib.sha256()
        with open(p, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        out.append(h.hexdigest())
    return out


def read_manifest(folder: Path) -> dict[str, Any]:
    """The deliver folder's manifest ({} when absent or unreadable: everything is rebuilt)."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) and isinstance(data.get("formats"), dict) else {}


def recipe(fmt: str, view: Any) -> dict[str, Any]:
    """What a deliverable is made with besides its frames: format, view transform, cadence."""
    try:
        from importlib.metadata import version

        tool = version("motion-farm")
    except Exception:  # not installed as a distribution (a source checkout on the path)
        tool = "source"
    return {"format": fmt, "view": getattr(view, "description", repr(view)), "recipe_version": RECIPE_VERSION, "motion": tool,
            "cadence": {"60i": "3:2 tff 23.976", "50i": "2:2 tff 25"}.get(fmt)}


def _outputs_present(entry: dict[str, Any], folder: Path) -> bool:
    """Every output the manifest lists for a format is still there, at its recorded size."""
    outs = entry.get("outputs")
    if not isinstance(outs, list) or not outs:
        return False
    for o in outs:
        if not isinstance(o, dict) or not isinstance(o.get("name"), str):
            return False
        p = folder / o["name"]
        if not p.exists() or (p.is_file() and p.stat().st_size != o.get("size")):
            return False
    return True


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


def deliver_and_record(req: RenderRequest, out_dir: Path, frame_paths: list[Path], wanted: tuple[str, ...], report: dict[str, Any],
                       report_path: Path | None, say: Callable[[str], None]) -> dict[str, Any]:
    """Assemble the deliverables from `frame_paths` (the run's selection, in order), each
    rebuilt only when its frames or recipe changed since it was made (or with
    --overwrite); print where each one is and record them in the report (rewritten in
    place) and in deliver/manifest.json."""
    from ..telecine.deliver import deliver
    from ..telecine.sequence import discover, select

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
    view = deliver_view(req)
    numbers = [int(Path(p).name.split(".")[-2]) for p in frame_paths]
    prefix = Path(frame_paths[0]).name.rsplit(".", 2)[0]
    try:
        seq = select(discover(Path(frame_paths[0]).parent, prefix, require_even_height=any(f in ("60i", "50i") for f in wanted), allow_gaps=True), numbers)
    except FrameIOError as exc:
        raise UsageError(f"--deliver: {exc}") from None
    manifest = read_manifest(folder)
    known = {k: v for e in manifest.get("formats", {}).values() if isinstance(e, dict) for k, v in (e.get("frame_files") or {}).items()}
    digests = frame_digests(list(seq.paths), known)
    frame_files = {p.name: {"size": p.stat().st_size, "mtime_ns": p.stat().st_mtime_ns, "sha256": d} for p, d in zip(seq.paths, digests)}
    made_from = hashlib.sha256(json.dumps([[n, d] for n, d in zip(numbers, digests)]).encode()).hexdigest()
    record: dict[str, Any] = {}
    status: dict[str, str] = {}
    for fmt in wanted:
        entry = manifest.get("formats", {}).get(fmt)
        how = recipe(fmt, view)
        fresh = (isinstance(entry, dict) and entry.get("made_from") == made_from and entry.get("recipe") == how
                 and _outputs_present(entry, folder) and not req.overwrite)
        if fresh:
            names = [o["name"] for o in entry["outputs"]]
            status[fmt] = "up to date"
            say(f"  {fmt}: up to date (frames {format_frames(numbers)} unchanged): " + ", ".join(str(folder / n) for n in names))
        else:
            with staging(folder, f"making the {fmt} deliverable in", prefix=f".staging-{fmt}-") as staged:
                done = deliver(seq.directory, staged, (fmt,), view=view, sequence=seq)[fmt]
                names = []
                for p in done:
                    top = Path(p).relative_to(staged).parts[0]
                    if top not in names:
                        names.append(top)
                for name in names:
                    publish_path(staged / name, folder / name)
            outputs = [{"name": n, "size": (folder / n).stat().st_size if (folder / n).is_file() else None, "rate": movie_rate(folder / n, fmt in ("60i", "50i"))} for n in names]
            entry = {"frames": format_frames(numbers), "made_from": made_from, "recipe": how, "outputs": outputs,
                     "frame_files": frame_files, "made_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            manifest.setdefault("formats", {})[fmt] = entry
            manifest["version"] = 1
            write_atomic(folder / MANIFEST, (json.dumps(manifest, indent=2) + "\n").encode(), "writing the deliverables' manifest")
            status[fmt] = "made"
            for n in names:
                p = folder / n
                rate = movie_rate(p, fmt in ("60i", "50i"))
                if p.is_dir():
                    say(f"  {fmt}: {len(list(p.glob('*.exr')))} frames in {p}")
                else:
                    say(f"  {fmt}: {p}" + (f" ({rate})" if rate else ""))
        rates = {o.get("name"): o.get("rate") for o in (manifest.get("formats", {}).get(fmt) or {}).get("outputs", []) if isinstance(o, dict)}
        for n in names:
            p = folder / n
            if p.is_dir():
                record[f"{fmt}_frames"] = [str(p)]
            else:
                record.setdefault(fmt, []).append(str(p))
                if rates.get(n):  # a movie's rate as read back: '23.976 fps (24000/1001)'
                    record.setdefault("rates", {})[str(p)] = rates[n]
    record["status"] = status
    record["frames"] = format_frames(numbers)
    report["deliverables"] = record
    if report_path is not None:  # None: no folder would take the report (a disk fault)
        write_report(report, report_path)
    return record
