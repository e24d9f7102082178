"""Deliverables from a rendered EXR sequence: what `motion render ... --deliver 24p,60i` runs.

Formats (names for `--deliver`):
  24p      ProRes 422 HQ .mov at the film rate
  60i      3:2 pulldown (or `pattern`) EXR sequence in `60i/` and its interlaced ProRes .mov
  50i      2:2 EXR sequence in `50i/` (film speed 25) and its interlaced ProRes .mov
  review   H.264 .mp4 at the film rate, for review
  contact  contact sheet PNG
The sequence is validated once, before anything is written.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import Callable, Iterable

from ..errors import UsageError
from .cadence import film_rate
from .contact_sheet import contact_sheet
from .convert import telecine_sequence
from .movie import ViewTransform, sequence_movie
from .sequence import Sequence, discover

FORMATS = ("24p", "60i", "50i", "review", "contact")

# Called as report(format name, step description) before each step.
Report = Callable[[str, str], None]


def parse_formats(text: str | Iterable[str]) -> tuple[str, ...]:
    """'24p,60i' -> ('24p', '60i'); UsageError naming an unknown format."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    unknown = [t for t in items if t not in FORMATS]
    if unknown or not items:
        raise UsageError(f"--deliver: unknown format {', '.join(unknown) or '(none)'}; choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(items))


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
) -> dict[str, list[Path]]:
    """Make the requested deliverables of the sequence in `in_dir` (or of `sequence`, a
    selection of its frames: sequence.select) under `out_dir`.

    Returns, per format, the paths written (movie, contact sheet; for 60i/50i the movie
    after the EXR frames).
    """
    wanted = parse_formats(formats)
    seq = sequence or discover(in_dir, prefix, require_even_height=any(f in ("60i", "50i") for f in wanted))
    out_dir = Path(out_dir)
    film = film_rate(film_speed)
    view = view or ViewTransform()  # (a bad OCIO config or view failed when it was made)
    say = report or (lambda fmt, step: None)
    done: dict[str, list[Path]] = {}
    for fmt in wanted:
        if fmt in ("24p", "review"):
            ext = ".mov" if fmt == "24p" else ".mp4"
            movie = out_dir / f"{seq.prefix}_{fmt}{ext}"
            say(fmt, f"movie {movie}")
            done[fmt] = [sequence_movie(seq, movie, rate=film, field_order=None,
                                        codec=codec if fmt == "24p" else "h264", view=view)]
        elif fmt in ("60i", "50i"):
            pat, speed = (pattern, film) if fmt == "60i" else ("2:2", Fraction(25))
            say(fmt, f"{pat} pulldown to {out_dir / fmt}")
            res = telecine_sequence(seq.directory, out_dir / fmt, pattern=pat, field_order=field_order,
                                    film_speed=speed, drop_frame=drop_frame and fmt == "60i",
                                    overwrite=overwrite, sequence=seq)
            movie = out_dir / f"{seq.prefix}_{fmt}.mov"
            say(fmt, f"movie {movie}")
            done[fmt] = list(res.paths) + [sequence_movie(res.out_dir, movie, codec=codec, view=view)]
        elif fmt == "contact":
            sheet = out_dir / f"{seq.prefix}_contact.png"
            say(fmt, f"contact sheet {sheet}")
            done[fmt] = [contact_sheet(seq, sheet, view=view)]
    return done
