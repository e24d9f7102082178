"""Deliverables from a rendered EXR sequence: what `motion render ... --deliver 24p,60i` runs.

The formats are records in one registry (`pipeline/deliverables.py`: 24p, 60i, 50i,
review, review25, contact); a deliverable is made by the maker of its record's kind
(`MAKERS`: a progressive movie, a pulldown to interlaced field frames and their movie, a
contact sheet), so no code here knows a format by its name. The sequence is validated
once, before anything is written.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..deliverables import FORMATS, DeliverFormat, parse_formats
from ..errors import UsageError
from ..field_model import weave_frames
from .cadence import film_rate, plan
from .contact_sheet import contact_sheet
from .convert import Result, telecine_sequence
from .movie import ViewedFrames, ViewTransform, choose_codec, encode_movie, first_timecode, sequence_movie
from .movie import viewed as viewed_frames
from .sequence import Sequence, discover

# Called as report(format name, step description) before each step.
Report = Callable[[str, str], None]


@dataclass(frozen=True)
class Options:
    """How a run's deliverables are made, beyond their records: the film speed of a
    format that takes the run's (23.976 for a 24 fps shot), the pulldown pattern of one
    at that speed, field order, drop-frame timecode, a forced codec, the view transform."""

    film: Fraction
    pattern: str
    field_order: str
    drop_frame: bool
    codec: str | None
    view: ViewTransform
    overwrite: bool
    shared: ViewedFrames | None = None  # the viewed frames a run's deliverables share


def _speed(fmt: DeliverFormat, opts: Options) -> Fraction:
    return film_rate(fmt.film_speed) if fmt.film_speed else opts.film


def _codec(fmt: DeliverFormat, opts: Options) -> str | None:
    """The record's codec; a forced one (--codec) replaces it for the ProRes .mov masters."""
    return opts.codec if opts.codec and fmt.suffix == ".mov" else fmt.codec


def _movie(fmt: DeliverFormat, seq: Sequence, out_dir: Path, tag: str, opts: Options, say: Report) -> list[Path]:
    movie = out_dir / f"{seq.prefix}_{tag}{fmt.suffix}"
    say(fmt.name, f"movie {movie}")
    return [sequence_movie(seq, movie, rate=_speed(fmt, opts), field_order=None, codec=_codec(fmt, opts), view=opts.view, shared=opts.shared)]


def _fields(fmt: DeliverFormat, seq: Sequence, out_dir: Path, tag: str, opts: Options, say: Report) -> list[Path]:
    pattern = opts.pattern if fmt.film_speed is None else (fmt.cadence or opts.pattern)
    say(fmt.name, f"{pattern} pulldown to {out_dir / tag}")
    res = telecine_sequence(seq.directory, out_dir / tag, pattern=pattern, field_order=opts.field_order,
                            film_speed=_speed(fmt, opts), drop_frame=opts.drop_frame and fmt.drop_frame_ok,
                            overwrite=opts.overwrite, sequence=seq, shared=opts.shared)
    movie = out_dir / f"{seq.prefix}_{tag}{fmt.suffix}"
    say(fmt.name, f"movie {movie}")
    return list(res.paths) + [woven_movie(seq, res, movie, codec=_codec(fmt, opts), view=opts.view, shared=opts.shared)]


def woven_movie(seq: Sequence, res: Result, path: Path, *, codec: str | None, view: ViewTransform, shared: ViewedFrames | None = None) -> Path:
    """The interlaced movie of a pulldown, woven from the film frames as the pulldown wove
    its EXR frames: each film frame read and viewed once (the view transform is per pixel,
    so weaving viewed frames gives the viewed woven frames, bit for bit), instead of
    reading every woven frame back from disk and viewing each."""
    if res.cadence.blend or res.field_order is None:
        return sequence_movie(res.out_dir, path, codec=codec, view=view)
    frames = plan(len(seq), res.cadence, res.field_order, "pad")
    need = sorted({i for vf in frames for i in (vf.top, vf.bottom)})
    viewed = zip(need, viewed_frames(seq, view, need, shared))
    kept: dict[int, np.ndarray] = {}

    def woven() -> Iterator[np.ndarray]:
        for vf in frames:
            while vf.top not in kept or vf.bottom not in kept:
                index, rgb16 = next(viewed)
                kept[index] = rgb16
            yield weave_frames(kept[vf.top], kept[vf.bottom])
            for index in [k for k in kept if k < min(vf.top, vf.bottom)]:
                del kept[index]

    chosen, container = choose_codec(path, codec)
    timecode = first_timecode(replace(seq, paths=res.paths[:1]))
    return encode_movie(path, chosen, container, woven(), res.rate, seq.width, seq.height, res.field_order, view, timecode, None, len(frames))


def _sheet(fmt: DeliverFormat, seq: Sequence, out_dir: Path, tag: str, opts: Options, say: Report) -> list[Path]:
    sheet = out_dir / f"{seq.prefix}_{tag}{fmt.suffix}"
    say(fmt.name, f"contact sheet {sheet}")
    return [contact_sheet(seq, sheet, view=opts.view)]


# kind -> maker(format, sequence, output folder, tag (names the outputs), options, report) -> paths written
MAKERS: dict[str, Callable[[DeliverFormat, Sequence, Path, str, Options, Report], list[Path]]] = {
    "movie": _movie,
    "fields": _fields,
    "sheet": _sheet,
}


def deliver(
    in_dir: str | Path,
    out_dir: str | Path,
    formats: str | Iterable[str] = ("24p", "60i"),
    *,
    pattern: str = "3:2",
    field_order: str = "tff",
    film_speed: str | Fraction = "23.976",
    drop_frame: bool = False,
    codec: str | None = None,
    view: ViewTransform | None = None,
    prefix: str | None = None,
    overwrite: bool = False,
    report: Report | None = None,
    sequence: Sequence | None = None,
    tags: dict[str, str] | None = None,
    shared: ViewedFrames | None = None,
) -> dict[str, list[Path]]:
    """Make the requested deliverables of the sequence in `in_dir` (or of `sequence`, a
    selection of its frames: sequence.select / sequence_of) under `out_dir`.

    `tags` names each format's outputs (`<prefix>_<tag>.mov`, a field folder `<tag>/`);
    by default the format's name. `shared`: the viewed frames of `sequence` that the
    run's deliverables share (movie.ViewedFrames), each frame viewed once for them all;
    by default one for this call's formats. Returns, per format, the paths written (movie, contact
    sheet; for a pulldown the field frames, then their movie).
    """
    wanted = parse_formats(formats)
    seq = sequence or discover(in_dir, prefix, require_even_height=any(FORMATS[f].interlaced for f in wanted))
    view = view or ViewTransform()  # (a bad OCIO view failed when it was made)
    opts = Options(film=film_rate(film_speed), pattern=pattern, field_order=field_order, drop_frame=drop_frame,
                   codec=codec, view=view, overwrite=overwrite, shared=shared if shared is not None else ViewedFrames(seq, view))
    say = report or (lambda fmt, step: None)
    return {f: MAKERS[FORMATS[f].kind](FORMATS[f], seq, Path(out_dir), (tags or {}).get(f, f), opts, say) for f in wanted}
