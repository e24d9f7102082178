"""`--deliver`: every check that could fail after the last frame runs before the first
(`check_deliver`); after the last frame the deliverables are assembled and recorded in the
report (`deliver_and_record`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import UsageError
from ..farm.frames import format_frames
from ..farm.report import write_report
from .request import RenderRequest


def deliver_view(req: RenderRequest) -> Any:
    """The deliverables' `ViewTransform` from the request's exposure and OCIO options."""
    from ..telecine.movie import ViewTransform

    return ViewTransform(**{k: v for k, v in req.deliver_view.items() if v is not None})


def check_deliver(req: RenderRequest, loaded: Any, frames: list[int], out_dir: Path, create: bool = True) -> None:
    """What `--deliver` would find wrong after the last frame, found before the first:
    format names, the view transform (OCIO config, display, view), interlaced formats on an
    odd height, a selection with gaps (the telecine needs a gapless sequence), the movie
    encoders, a deliver folder that cannot be created."""
    from ..telecine.deliver import parse_formats
    from ..telecine.movie import CODECS

    wanted = parse_formats(req.deliver or "")
    deliver_view(req)  # a bad OCIO config, display or view
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

    done = deliver(out_dir, out_dir / "deliver", parse_formats(req.deliver or ""), view=deliver_view(req))
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
