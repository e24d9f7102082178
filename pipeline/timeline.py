"""Exact time: frame <-> seconds <-> shutter interval, with rational frame rates.

Frame rates are `fractions.Fraction` (24, 25, 30000/1001 ...); frame times are exact
rationals, converted to float only at the boundary to numeric code.

>>> tl = Timeline(fps=Fraction(24), first=0, last=47)
>>> tl.seconds(24)
Fraction(1, 1)
>>> tl.frames
range(0, 48)
>>> tl.shutter(12, angle=180, position="center")
(Fraction(47, 96), Fraction(49, 96))
>>> tl.shutter(12, angle=180, position="start")
(Fraction(1, 2), Fraction(25, 48))
>>> parse_fps("30000/1001")
Fraction(30000, 1001)
>>> Timeline(fps=parse_fps("30000/1001"), first=0, last=0).seconds(30)
Fraction(1001, 1000)
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Literal, Sequence

ShutterPosition = Literal["start", "center", "end"]

# Limits (docs/scene-format.md, "Limits"): what a timeline or a frame selection may ask for.
MAX_FRAMES = 1_000_000  # frames in a timeline and in one job's selection (11.5 h at 24 fps)
MAX_FRAME_NUMBER = 10**9  # |frame number|
MIN_FPS = Fraction(1, 1000)  # one frame per 1000 s
MAX_FPS = Fraction(100_000)
MAX_FPS_TERM = 10**9  # numerator and denominator of a rational rate


# The NTSC family: N x 1000/1001 frames/s. Studios write these rates as decimals rounded to 2
# or 3 places (23.976, 23.98, 29.97, 47.952, 59.94, 119.88) and mean the exact ratio, which
# is what their timecode (drop-frame at 29.97 and 59.94) and every deliverable assume.
NTSC_BASES = (24, 30, 48, 60, 120, 240)


def _ntsc_rate(decimal: str) -> Fraction | None:
    """N x 1000/1001 when `decimal` is that rate rounded to 2 or 3 places, else None."""
    whole, dot, places = decimal.strip().partition(".")
    if len(decimal) > 16 or not dot or len(places) not in (2, 3) or not (whole + places).isdigit():
        return None
    written = Fraction(decimal.strip())
    for n in NTSC_BASES:
        exact = Fraction(n * 1000, 1001)
        if round(exact, len(places)) == written:
            return exact
    return None


def parse_fps(value: int | float | str | Fraction) -> Fraction:
    """Parse a frame rate: an integer, a decimal, or a rational string such as "30000/1001".
    A decimal that names an NTSC rate as studios write it (23.976, 23.98, 29.97, 59.94 ...)
    is that rate exactly (N x 1000/1001), never the decimal (2997/100 at 29.97).

    Raises ValueError (with the reason) for anything else, or a rate that is not > 0.

    >>> parse_fps(25), parse_fps("24000/1001"), parse_fps("23.976"), parse_fps(29.97), parse_fps("59.94")
    (Fraction(25, 1), Fraction(24000, 1001), Fraction(24000, 1001), Fraction(30000, 1001), Fraction(60000, 1001))
    >>> parse_fps(29.9), parse_fps("29.970")
    (Fraction(299, 10), Fraction(30000, 1001))
    """
    shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
    if isinstance(value, bool):
        raise ValueError("expected a frame rate (integer or 'num/den' string), got a boolean")
    ntsc = _ntsc_rate(repr(value) if isinstance(value, float) else value) if isinstance(value, (float, str)) else None
    if ntsc is not None:
        return ntsc
    try:
        if isinstance(value, float):
            rate = Fraction(value).limit_denominator(1001000)
        elif isinstance(value, str) and "/" in value:
            num, den = value.split("/", 1)
            rate = Fraction(int(num.strip()), int(den.strip()))
        else:
            rate = Fraction(value)
    except (ValueError, ZeroDivisionError, TypeError, OverflowError):
        raise ValueError(
            f"expected a frame rate as an integer or 'num/den' string, got {shown}"
        ) from None
    if rate <= 0:
        raise ValueError(f"frame rate must be > 0, got {shown}")
    if rate.numerator > MAX_FPS_TERM or rate.denominator > MAX_FPS_TERM:
        raise ValueError(f"frame rate {shown}: numerator and denominator are limited to {MAX_FPS_TERM}")
    if not MIN_FPS <= rate <= MAX_FPS:
        raise ValueError(f"frame rate must be between {MIN_FPS} and {MAX_FPS} frames/s, got {shown}")
    return rate


@dataclass(frozen=True)
class Timeline:
    """A shot's frame range on an exact time base. Frame f starts at time f / fps."""

    fps: Fraction
    first: int
    last: int

    @property
    def frames(self) -> range:
        """The frame numbers first..last."""
        return range(self.first, self.last + 1)

    @property
    def frame_duration(self) -> Fraction:
        """Seconds per frame, exact (1 / fps)."""
        return 1 / self.fps

    def seconds(self, frame: int | Fraction) -> Fraction:
        """Time in seconds of a (possibly fractional) frame number."""
        return Fraction(frame) / self.fps

    def frame_at(self, seconds: Fraction | float) -> Fraction:
        """Fractional frame number at a time in seconds."""
        return Fraction(seconds) * self.fps

    def shutter(
        self, frame: int, angle: float | Fraction, position: ShutterPosition = "center"
    ) -> tuple[Fraction, Fraction]:
        """Shutter interval [open, close] in seconds for a frame.

        The shutter is open for angle/360 of a frame's duration. `start` opens at the
        frame's time, `end` closes at it, `center` straddles it symmetrically.
        """
        open_for = Fraction(angle) / 360 * self.frame_duration
        t = self.seconds(frame)
        if position == "start":
            return t, t + open_for
        if position == "end":
            return t - open_for, t
        if position == "center":
            return t - open_for / 2, t + open_for / 2
        raise ValueError(f"shutter position must be start, center or end, got {position!r}")


def rate_label(fps: Fraction | float | int) -> str:
    """A frame rate as people read it, exact where that matters: '24 fps', '23.976 fps
    (24000/1001)', '29.97 fps (30000/1001)'.

    >>> rate_label(Fraction(24000, 1001))
    '23.976 fps (24000/1001)'
    >>> rate_label(Fraction(25))
    '25 fps'
    """
    f = Fraction(fps).limit_denominator(1_000_000)
    if f.denominator == 1:
        return f"{f.numerator} fps"
    shown = f"{float(f):.3f}".rstrip("0").rstrip(".")
    return f"{shown} fps ({f.numerator}/{f.denominator})"


def frame_timecode(frame: int, fps: Fraction, drop_frame: bool = False) -> str | None:
    """The timecode of frame number `frame` (not of its place in a range): frames are
    counted at the nominal rate from 00:00:00:00 at frame 0, as telecine does, so frame
    1001 of a 24 or 23.976 fps shot is 00:00:41:17 (1001 = 41 x 24 + 17) whatever frame a
    render starts at. None for a negative frame number (timecode has no sign) and for a
    rate under 1 frame a second (its frame field would count nothing: fps 0.001).

    >>> frame_timecode(1001, Fraction(24000, 1001))
    '00:00:41:17'
    >>> frame_timecode(3, Fraction(1, 1000)) is None
    True
    """
    return timecode(frame, fps, drop_frame) if frame >= 0 and round(fps) >= 1 else None


def timecode(frame: int, fps: Fraction, drop_frame: bool = False) -> str:
    """SMPTE timecode HH:MM:SS:FF (or HH:MM:SS;FF drop-frame) of a 0-based frame count.

    Drop-frame skips frame numbers 0 and 1 (2 per minute at 29.97; 4 at 59.94) in every
    minute not divisible by ten, so the label stays within 1 frame per hour of wall time.

    >>> timecode(0, Fraction(24))
    '00:00:00:00'
    >>> timecode(1800, Fraction(30000, 1001), drop_frame=True)
    '00:01:00;02'
    >>> timecode(17982, Fraction(30000, 1001), drop_frame=True)
    '00:10:00;00'
    """
    nominal = round(fps)
    if drop_frame:
        if nominal not in (30, 60) or fps.denominator != 1001:
            raise ValueError("drop-frame timecode applies to 30000/1001 and 60000/1001 only")
        drop = 2 * nominal // 30
        per_10min = nominal * 600 - drop * 9
        per_min = nominal * 60 - drop
        tens, rest = divmod(frame, per_10min)
        # The first minute of each ten keeps all its numbers; later ones drop `drop` each.
        extra = 0 if rest < drop else drop * ((rest - drop) // per_min)
        frame = frame + drop * 9 * tens + extra
    ff = frame % nominal
    ss = frame // nominal % 60
    mm = frame // (nominal * 60) % 60
    hh = frame // (nominal * 3600) % 24
    sep = ";" if drop_frame else ":"
    return f"{hh:02d}:{mm:02d}:{ss:02d}{sep}{ff:02d}"


# SMPTE ST 12-1 counts at most 30 frames a second in its frame field; a faster rate is
# counted in groups of `timecode_group(fps)` frames (pairs at 48, 50, 59.94 and 60 fps).
MAX_TIMECODE_FRAMES = 30


def timecode_group(fps: Fraction | int) -> int:
    """How many frames share one value of the timecode's frame field: 1 up to 30 frames/s,
    2 (the frame pair of SMPTE ST 12-1) up to 60, 4 at 120 (ceil(nominal / 30) in general).

    >>> [timecode_group(Fraction(n)) for n in (24, 30, 48, 50, 60)], timecode_group(Fraction(120000, 1001))
    ([1, 1, 2, 2, 2], 4)
    """
    return max(1, -(-round(fps) // MAX_TIMECODE_FRAMES))


def timecode_fields(label_frame: int, fps: Fraction | int) -> tuple[int, int]:
    """A timecode label's frame number FF (0 .. nominal-1, as `timecode` writes it) as the
    frame field of a SMPTE ST 12 time address and the frame's place in its group: at 60
    fps label 45 is field 22, second of its pair (the pair flag set); at 24 fps it is itself.

    >>> timecode_fields(45, Fraction(60)), timecode_fields(45, Fraction(120)), timecode_fields(17, Fraction(24))
    ((22, 1), (11, 1), (17, 0))
    """
    return divmod(label_frame, timecode_group(fps))


def format_frames(frames: Sequence[int]) -> str:
    """Compact text in the `--frames` grammar: [1,2,3,7] -> '1-3,7'; [0,2,4,6] -> '0-6x2'.

    >>> format_frames([0, 2, 4, 6, 9, 10])
    '0-6x2,9,10'
    """
    fs = sorted(set(frames))
    parts: list[str] = []
    i = 0
    while i < len(fs):
        j = i
        if i + 1 < len(fs):
            step = fs[i + 1] - fs[i]
            while j + 1 < len(fs) and fs[j + 1] - fs[j] == step:
                j += 1
        if j - i >= 2:
            parts.append(f"{fs[i]}-{fs[j]}" + (f"x{step}" if step != 1 else ""))
            i = j + 1
        else:
            parts.append(str(fs[i]))
            i += 1
    return ",".join(parts)
