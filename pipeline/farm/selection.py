"""Frame selection: the `--frames` grammar, `--shard I/N` partitions and chunks.

Grammar (Blender-like, comma-separated parts, each one of):

    N          one frame                     7
    A-B        inclusive range               0-119
    A-BxS      every S-th frame from A       0-119x2  (0, 2, ... 118)

Parts may mix (`1,5,10-20x5`); the result is sorted and each frame appears once.
Negative frames are allowed (`-5--1`, or `-5..-1`: ranges that start below 0 are printed
`A..B`, timeline.format_range, and read back as written).
"""

from __future__ import annotations

import math
import re
from typing import Sequence

from ..errors import UsageError
from ..timeline import MAX_FRAME_NUMBER, MAX_FRAMES, format_frames, format_range  # noqa: F401  (format_frames: re-exported for farm)

_PART = re.compile(r"^(-?\d+)(?:(?:-|\.\.)(-?\d+)(?:x(\d+))?)?$")  # A-B, or A..B (as ranges from below 0 are printed)


def parse_frames(spec: str, first: int | None = None, last: int | None = None) -> list[int]:
    """Parse a `--frames` spec into sorted unique frame numbers.

    When `first`/`last` are given, frames outside the scene's timeline are an error.

    >>> parse_frames("0-9x3,4,1")
    [0, 1, 3, 4, 6, 9]
    """
    if not spec or not spec.strip():
        raise UsageError("--frames: empty frame spec; expected e.g. 0-119, 0-119x2 or 1,5,9")
    shown = spec if len(spec) <= 60 else spec[:57] + "..."
    parts: list[range] = []
    total = 0
    for raw in spec.split(","):
        part = raw.strip().replace(" ", "")
        m = _PART.match(part)
        if not m:
            raise UsageError(f"--frames: cannot read {raw.strip()[:40]!r} in {shown!r}; expected N, A-B or A-BxSTEP (e.g. 0-119x2)")
        a, b, step = m.group(1), m.group(2), m.group(3)
        if any(g is not None and len(g.lstrip("-")) > 10 for g in (a, b, step)):
            raise UsageError(f"--frames: {part[:40]!r}: frame numbers are limited to +-{MAX_FRAME_NUMBER}")
        lo = int(a)
        hi = int(b) if b is not None else lo
        s = int(step) if step is not None else 1
        if hi < lo:
            raise UsageError(f"--frames: range {part!r} is reversed (write {hi}-{lo})")
        if s < 1:
            raise UsageError(f"--frames: step in {part!r} must be at least 1")
        if max(abs(lo), abs(hi)) > MAX_FRAME_NUMBER:
            raise UsageError(f"--frames: {part!r}: frame numbers are limited to +-{MAX_FRAME_NUMBER}")
        r = range(lo, hi + 1, s)
        if first is not None and last is not None and (lo < first or r[-1] > last):
            # name the frames outside without listing a huge range one by one
            outside = [x for x in (range(lo, min(hi, first - 1) + 1, s), range(max(lo, last + 1), hi + 1, s)) if len(x)]
            text = ",".join(format_frames(x) if len(x) <= 1000 else format_range(x[0], x[-1], x.step) for x in outside)
            raise UsageError(f"--frames: {text} outside the scene's timeline {format_range(first, last)}")
        total += len(r)  # an upper bound on the selection (parts may overlap)
        if total > MAX_FRAMES:
            raise UsageError(f"--frames: {shown!r} selects more than {MAX_FRAMES} frames (the limit for one job)")
        parts.append(r)
    frames: set[int] = set()
    for r in parts:
        frames.update(r)
    return sorted(frames)


def parse_shard(spec: str) -> tuple[int, int]:
    """'I/N' (1-based) -> (I, N)."""
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", spec or "")
    if not m:
        raise UsageError(f"--shard: expected I/N such as 2/4, got {spec!r}")
    i, n = int(m.group(1)), int(m.group(2))
    if n < 1 or not 1 <= i <= n:
        raise UsageError(f"--shard: {spec!r} needs 1 <= I <= N")
    return i, n


def shard(frames: Sequence[int], index: int, count: int) -> list[int]:
    """The `index`-th (1-based) of `count` balanced contiguous parts of `frames`.

    Part sizes differ by at most one (the first `len % count` parts get the extra frame);
    contiguous parts keep each shard's frames together (warm caches, simple checks).
    """
    if count < 1 or not 1 <= index <= count:
        raise UsageError(f"--shard: {index}/{count} needs 1 <= I <= N")
    n = len(frames)
    base, extra = divmod(n, count)
    k = index - 1
    start = k * base + min(k, extra)
    size = base + (1 if k < extra else 0)
    return list(frames[start : start + size])


def default_chunk_size(n_frames: int, n_workers: int) -> int:
    """About four chunks per worker (load balance, small retry unit), at most 8 frames."""
    if n_frames <= 0:
        return 1
    return max(1, min(8, math.ceil(n_frames / (max(1, n_workers) * 4))))


def chunks(frames: Sequence[int], size: int) -> list[list[int]]:
    """Split the (sorted) selection into runs of up to `size` consecutive selected frames."""
    if size < 1:
        raise UsageError(f"--chunk-size must be at least 1, got {size}")
    out: list[list[int]] = []
    for f in frames:
        if out and len(out[-1]) < size:
            out[-1].append(f)
        else:
            out.append([f])
    return out
