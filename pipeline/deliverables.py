"""Deliverable formats as records, one registry (as the lights are): what `--deliver NAME`
and a scene's `output.deliver` may name, and everything known about each format.

A format is one `DeliverFormat` record: its kind (a progressive movie, a pulldown to
interlaced field frames and their movie, or a contact sheet), the codec and container of
its movie, the cadence and film speed of a pulldown. `telecine/deliver.py` makes a
deliverable by dispatching on the record's kind (one maker per kind, none per format
name); the scene schema's list of allowed names, the shot stage's checks (gapless runs,
even heights, encoders) and the manifest's recipe all read the record. Adding a format
(a 25p review movie, a 50i PAL master) is one `register(DeliverFormat(...))` here.

This module sits low (beside the timeline) because the scene schema validates the names.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

from .errors import UsageError

# `--ocio none` (or one of these names): the deliverables' view is the plain sRGB curve, no
# OCIO config (telecine/movie.py ViewTransform)
PLAIN_VIEW = ("none", "plain", "srgb")

Kind = Literal["movie", "fields", "sheet"]


@dataclass(frozen=True)
class DeliverFormat:
    """One deliverable format.

    kind:       movie (the frames as a progressive movie), fields (a pulldown to
                interlaced EXR frames in a folder, and their interlaced movie), sheet
                (a contact sheet PNG).
    codec:      the movie's codec (telecine/movie.py CODECS); suffix its file's extension.
    film_speed: the rate the film frames play at; None: the run's film speed (23.976,
                what a 24 fps shot is telecined at).
    cadence:    a pulldown's field pattern ("3:2", "2:2"); kind fields only.
    """

    name: str
    kind: Kind
    description: str
    suffix: str = ""
    codec: str | None = None
    film_speed: str | None = None
    cadence: str | None = None

    @property
    def gapless(self) -> bool:
        """Whether the format needs a gapless run of frames (a movie does; a sheet is a glance)."""
        return self.kind != "sheet"

    @property
    def interlaced(self) -> bool:
        """Whether its frames are woven from two fields (an even height is needed)."""
        return self.kind == "fields"

    @property
    def drop_frame_ok(self) -> bool:
        """Whether a drop-frame timecode applies (an NTSC-rate pulldown)."""
        return self.kind == "fields" and self.film_speed is None

    def recipe(self) -> dict[str, str | None]:
        """What a deliverable of this format is made with, for the manifest (a change of any
        of it rebuilds the deliverable)."""
        return {"kind": self.kind, "codec": self.codec, "suffix": self.suffix,
                "cadence": f"{self.cadence} tff {self.film_speed or 'film'}" if self.cadence else None,
                "film_speed": self.film_speed}


FORMATS: dict[str, DeliverFormat] = {}


def register(fmt: DeliverFormat) -> DeliverFormat:
    """Enter `fmt` in the registry (a name is registered once)."""
    if fmt.name in FORMATS:
        raise ValueError(f"deliverable format {fmt.name!r} is registered twice")
    FORMATS[fmt.name] = fmt
    return fmt


register(DeliverFormat("24p", "movie", "ProRes 422 HQ .mov at the film rate", ".mov", codec="prores"))
register(DeliverFormat("60i", "fields", "3:2 pulldown EXR frames in 60i/ and their interlaced ProRes .mov", ".mov",
                       codec="prores", cadence="3:2"))
register(DeliverFormat("50i", "fields", "2:2 EXR frames in 50i/ (film speed 25) and their interlaced ProRes .mov", ".mov",
                       codec="prores", cadence="2:2", film_speed="25"))
register(DeliverFormat("review", "movie", "H.264 .mp4 at the film rate, for review", ".mp4", codec="h264"))
register(DeliverFormat("review25", "movie", "H.264 .mp4 at 25 fps (PAL speed), for review", ".mp4", codec="h264", film_speed="25"))
register(DeliverFormat("contact", "sheet", "contact sheet PNG", ".png"))

NAMES: tuple[str, ...] = tuple(FORMATS)


def parse_formats(text: str | Iterable[str]) -> tuple[str, ...]:
    """'24p,60i' -> ('24p', '60i'); UsageError naming an unknown format."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    unknown = [t for t in items if t not in FORMATS]
    if unknown or not items:
        raise UsageError(f"--deliver: unknown format {', '.join(unknown) or '(none)'}; choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(items))
