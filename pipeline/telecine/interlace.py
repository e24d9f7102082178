"""Interlaced frames from rendered fields (`motion render --fields 60i`, shot/fields.py).

A field is a timeline instant of its own: at 60i the fields are the frames of a
60000/1001 fields/s timeline, each with the scene's shutter angle of its own field
duration. `field_range` says which fields cover a shot's frames; the renderer draws only a
field's rows (FrameRenderer.render_layers(field=...)); `weave_fields` pairs fields 2k (the field order's first
parity) and 2k + 1 into interlaced frame k at half the field rate, with the field order
and each field's time in the header, and an interlaced movie. Compare 3:2 pulldown
(telecine_sequence), whose fields repeat 24p film frames: a frame there shows at most two
film times; here every field has its own.

>>> from fractions import Fraction
>>> field_range(Fraction(24), 0, 23, FIELD_RATES["60i"])   # one second of 24p
(0, 59)
"""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FrameIOError, UsageError
from ..field_model import FieldOrder, check_field_order, parity_of

FIELD_RATES: dict[str, Fraction] = {"60i": Fraction(60000, 1001), "50i": Fraction(50)}


def field_rate(name: str) -> Fraction:
    """The field rate of `60i` (60000/1001) or `50i` (50); UsageError otherwise."""
    if name not in FIELD_RATES:
        raise UsageError(f"--fields expects one of {', '.join(FIELD_RATES)}, got {name!r}")
    return FIELD_RATES[name]


def field_range(fps: Fraction, first: int, last: int, rate: Fraction) -> tuple[int, int]:
    """First and last field (an even first, an odd last: whole interlaced frames) covering
    the scene's frames first..last, i.e. the seconds [first / fps, (last + 1) / fps)."""
    start = Fraction(first) / fps * rate
    end = Fraction(last + 1) / fps * rate
    f0 = math.floor(start)
    f0 -= f0 % 2
    f1 = math.ceil(end) - 1
    if f1 % 2 == 0:
        f1 += 1
    return f0, max(f1, f0 + 1)


def weave_fields(
    field_dir: str | Path,
    out_dir: str | Path,
    name: str,
    order: str,
    rate: Fraction,
    *,
    movie: bool = True,
    pixel_type: str = "half",
    compression: str = "zip",
) -> list[Path]:
    """Pair fields 2k and 2k + 1 of `field_dir` into interlaced EXR frames k (numbered
    field // 2) at rate / 2 in `out_dir`, with `fieldOrder` and each field's time and
    source in the header; and an interlaced movie `{name}_{rate}i.mov` when asked."""
    from ..frame_output import read_frame, write_frame
    from ..timeline import timecode
    from ..field_model import weave
    from .movie import write_movie
    from .sequence import find_sequences, frame_digits

    fo: FieldOrder = check_field_order(order)
    field_dir, out_dir = Path(field_dir), Path(out_dir)
    found = dict(find_sequences(field_dir).get(name, []))
    if not found:
        raise FrameIOError(f"{field_dir}: no fields named {name}.NNNN.exr to weave")
    pairs = sorted({f // 2 for f in found})
    missing = [f for k in pairs for f in (2 * k, 2 * k + 1) if f not in found]
    if missing:
        raise FrameIOError(f"{field_dir}: fields {missing[:8]} are missing; every interlaced frame needs both of its fields")
    frame_rate = rate / 2
    drop = frame_rate.denominator == 1001
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    woven: list[np.ndarray] = []
    for k in pairs:
        first, second = read_frame(found[2 * k]), read_frame(found[2 * k + 1])
        by_parity = {parity_of(2 * k, fo): first, parity_of(2 * k + 1, fo): second}
        top, bottom = by_parity["top"], by_parity["bottom"]
        rgba = weave(top.rgba, bottom.rgba)
        aovs: dict[str, Any] = {}
        for layer in top.aovs:
            aovs[layer] = weave(top.aovs[layer], bottom.aovs[layer])
        meta = {key: v for key, v in first.meta.items() if key not in ("frame", "time", "shutter_open", "shutter_close", "motion_hash", "field")}
        meta.update(
            frame=k,
            fieldOrder=fo,
            fieldRendered=True,
            fieldRate=str(rate),
            firstFieldSource=2 * k,
            secondFieldSource=2 * k + 1,
            firstFieldTime=float(first.meta["time"]),
            secondFieldTime=float(second.meta["time"]),
            firstFieldShutter=f"{first.meta['shutter_open']},{first.meta['shutter_close']}",
            secondFieldShutter=f"{second.meta['shutter_open']},{second.meta['shutter_close']}",
            time=float(first.meta["time"]),
        )
        path = out_dir / f"{name}.{frame_digits(k)}.exr"
        write_frame(path, rgba, meta, fps=frame_rate, timecode=timecode(k, frame_rate, drop_frame=drop),
                    pixel_type=pixel_type, compression=compression, aovs=aovs or None)  # type: ignore[arg-type]
        written.append(path)
        if movie:
            woven.append(rgba)
    if movie and woven:
        h, w = woven[0].shape[:2]
        if h % 2:
            raise FrameIOError(f"{written[0]}: odd height {h}; interlaced fields need an even number of rows")
        label = "60i" if rate == FIELD_RATES["60i"] else "50i" if rate == FIELD_RATES["50i"] else f"{float(rate):g}i"
        written.append(write_movie(out_dir / f"{name}_{label}.mov", iter(woven), frame_rate, width=w, height=h, field_order=fo))
    return written
