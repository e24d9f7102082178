"""Pulldown cadences: which film frame feeds each field of the video.

A cadence lists how many fields each film frame of one cycle contributes. The usual
"3:2" pulldown (also called 2:3) is (2, 3): film frames A B C D become the ten fields
A A B B B C C D D D, paired into five video frames. With top field first:

    video frame   0      1      2      3      4
    top field     A      B      B      C      D
    bottom field  A      B      C      D      D

`2:3:3:2` (advanced pulldown) is (2, 3, 3, 2): A A B B B C C C D D, i.e. At/Ab Bt/Bb
Bt/Cb Ct/Cb Dt/Db; only frame 2 mixes two film frames, so inverse telecine drops it whole.
`2:2` (25p -> 50i) gives each film frame both fields of one video frame. Any other cadence
is written as its field counts: "3:2" read literally is the alias above, "32" or "3:2:2"
etc. are taken digit by digit (FFmpeg's `telecine=pattern=` convention).

Sequences whose length is not a multiple of the cycle simply stop part-way through it:
every film frame still gives its fields; if that leaves one unpaired field at the end,
`tail="pad"` (the default) completes the last video frame with the other field of the
same film frame (so no film frame is lost and inverse telecine recovers all of them),
while `tail="drop"` discards it, as FFmpeg's filter does.

>>> parse_cadence("3:2").counts, parse_cadence("2:3:3:2").counts, parse_cadence("32").counts
((2, 3), (2, 3, 3, 2), (3, 2))
>>> [(v.top, v.bottom) for v in plan(4, parse_cadence("3:2"), "tff")]
[(0, 0), (1, 1), (1, 2), (2, 3), (3, 3)]
>>> parse_cadence("3:2").rate_ratio
Fraction(5, 4)
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from fractions import Fraction
from typing import Literal

from ..errors import UsageError
from ..timeline import parse_fps
from ..field_model import FieldOrder, Parity, check_field_order, first_parity, second_parity

Tail = Literal["pad", "drop"]

# Named cadences: industry names -> fields per film frame of one cycle.
NAMED: dict[str, tuple[int, ...]] = {
    "3:2": (2, 3),
    "2:3": (2, 3),
    "2:3:3:2": (2, 3, 3, 2),
    "2:2": (2, 2),
}

NTSC_FILM = Fraction(24000, 1001)


@dataclass(frozen=True)
class Cadence:
    """A pulldown cadence: `counts[i]` fields from film frame i of each cycle.

    `blend` marks the seed's progressive comparison variant: each output frame is the
    average of the film frames its two fields would have come from (repeat, repeat,
    blend, blend, repeat for 3:2), instead of interlaced fields.
    """

    name: str
    counts: tuple[int, ...]
    blend: bool = False

    @property
    def fields_per_cycle(self) -> int:
        """Fields in one cycle of the cadence (10 for 3:2)."""
        return sum(self.counts)

    @property
    def rate_ratio(self) -> Fraction:
        """Video frames per film frame: fields per cycle / (2 * film frames per cycle)."""
        return Fraction(self.fields_per_cycle, 2 * len(self.counts))

    @property
    def ffmpeg_pattern(self) -> str:
        """The same cadence as FFmpeg's `telecine=pattern=` string."""
        return "".join(str(c) for c in self.counts)

    def fields_of(self, frame_index: int) -> int:
        """How many fields film frame `frame_index` gives."""
        return self.counts[frame_index % len(self.counts)]


MAX_CADENCE_FRAMES = 64  # film frames in one pulldown cycle (3:2 has 2, 2:3:3:2 has 4)


def parse_cadence(text: str) -> Cadence:
    """A cadence from its name ("3:2", "2:3:3:2", "2:2", "blend") or its field counts.

    Field counts are written with colons ("2:3:2:3:3") or as FFmpeg digits ("23", "2332");
    each count is 0..9, at least one is non-zero.
    """
    text = str(text).strip()
    if text == "blend":
        return Cadence("blend", NAMED["3:2"], blend=True)
    if text.startswith("blend:"):
        inner = parse_cadence(text[len("blend:"):])
        return Cadence(text, inner.counts, blend=True)
    if text in NAMED:
        return Cadence(text, NAMED[text])
    if re.fullmatch(r"\d(:\d)*", text) or re.fullmatch(r"\d+", text):
        counts = tuple(int(c) for c in text.replace(":", ""))
        if len(counts) > MAX_CADENCE_FRAMES:
            raise UsageError(f"cadence of {len(counts)} field counts: a pulldown cycle has at most {MAX_CADENCE_FRAMES} film frames")
        if sum(counts) == 0:
            raise UsageError(f"cadence {text!r} gives no fields at all")
        return Cadence(text, counts)
    raise UsageError(
        f"unknown pulldown pattern {text!r}: expected 3:2, 2:3:3:2, 2:2, blend, "
        "or field counts such as 2:3:3:2 or 2332"
    )


def field_sources(n_frames: int, cadence: Cadence, tail: Tail = "pad") -> list[int]:
    """Film frame index of every field of the video, in time order.

    Film frame i contributes `cadence.fields_of(i)` consecutive fields. An odd total leaves
    one field unpaired at the end: `pad` adds the other field of the same film frame,
    `drop` removes it.
    """
    if tail not in ("pad", "drop"):
        raise UsageError(f"tail must be 'pad' or 'drop', got {tail!r}")
    sources = [i for i in range(n_frames) for _ in range(cadence.fields_of(i))]
    if len(sources) % 2:
        if tail == "pad":
            sources.append(sources[-1])
        else:
            sources.pop()
    return sources


@dataclass(frozen=True)
class VideoFrame:
    """One interlaced video frame: the film frame (0-based index) feeding each field."""

    index: int
    first: int
    second: int
    order: FieldOrder

    @property
    def top(self) -> int:
        """The film frame of the top field."""
        return self.first if self.order == "tff" else self.second

    @property
    def bottom(self) -> int:
        """The film frame of the bottom field."""
        return self.second if self.order == "tff" else self.first

    def source(self, parity: Parity) -> int:
        """The film frame of the field of `parity`."""
        return self.top if parity == "top" else self.bottom

    @property
    def first_parity(self) -> Parity:
        """The parity of the temporally first field."""
        return first_parity(self.order)

    @property
    def second_parity(self) -> Parity:
        """The parity of the temporally second field."""
        return second_parity(self.order)


def plan(n_frames: int, cadence: Cadence, order: FieldOrder, tail: Tail = "pad") -> list[VideoFrame]:
    """The video frames made from `n_frames` film frames: fields 2k and 2k+1 pair into frame k.

    Field 2k has the first parity of `order`, field 2k+1 the second, so the repeated field
    of a 3-field film frame lands on the other parity every other time, which is what
    makes 3:2 alternate "clean" and "mixed" video frames.
    """
    check_field_order(order)
    sources = field_sources(n_frames, cadence, tail)
    return [VideoFrame(k, sources[2 * k], sources[2 * k + 1], order) for k in range(len(sources) // 2)]


MAX_FILM_SPEED = 1000  # frames/s


def film_rate(film_speed: str | Fraction | int) -> Fraction:
    """The film rate for a --film-speed value: "23.976" means exactly 24000/1001."""
    if isinstance(film_speed, str) and film_speed.strip() in ("23.976", "23.98"):
        return NTSC_FILM
    if isinstance(film_speed, str) and film_speed.strip() in ("29.97",):
        return Fraction(30000, 1001)
    if isinstance(film_speed, str) and film_speed.strip() in ("59.94",):
        return Fraction(60000, 1001)
    try:
        rate = parse_fps(film_speed)
    except ValueError as exc:
        raise UsageError(f"--film-speed: {exc}") from None
    if not 1 <= rate <= MAX_FILM_SPEED:
        raise UsageError(f"--film-speed {film_speed}: expected a rate from 1 to {MAX_FILM_SPEED} frames/s (timecode counts whole frames a second)")
    return rate


def output_rate(film: Fraction, cadence: Cadence) -> Fraction:
    """Video frame rate from the film rate.

    rate = film * fields per cycle / (2 * frames per cycle): 24000/1001 * 5/4 = 30000/1001
    for 3:2 (24 -> 30 in exact mode), 25 * 1 = 25 frames (50 fields) for 2:2.
    """
    return Fraction(film) * cadence.rate_ratio
