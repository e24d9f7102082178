"""Inverse telecine: find which film frame fed each field, then weave the film frames back.

A pulldown repeats some fields. Between field k and field k+2 (same parity, one video
frame apart) the difference is zero exactly when both come from the same film frame, so
the zeros of d[k] = mean |field[k+2] - field[k]| spell out the cadence and its phase:
3:2 repeats fields 2 and 7 of every ten, 2:3:3:2 fields 2 and 5, 2:2 none. Detection
tries each candidate cadence at each phase and keeps the one whose predicted repeats are
all zero (no violation) and which leaves the fewest zeros unexplained; on a still shot
several fit equally, and then every choice gives the same pictures.

The field order is not detected: a 3:2 sequence read with the wrong order repeats fields
with the spacing of 2:3:3:2, so the two cannot be told apart by repeats alone. It comes
from the frames' metadata or from the caller.

Recovery takes, for each film frame, its top field from the first video frame that
carries it and its bottom field likewise; on frames we made this is bit-exact. A film
frame that has only one field inside the clip (a clip cut mid-cycle, or FFmpeg's dropped
tail field) is left out when it is the first or last one, and is an error in the middle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from ..errors import FrameIOError
from .cadence import Cadence, parse_cadence
from ..field_model import FieldOrder, Parity, first_parity, second_parity, weave_frames

CANDIDATES: tuple[str, ...] = ("3:2", "2:3:3:2", "2:2")


def field_differences(frames: Iterable[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean absolute difference of the top fields, and of the bottom fields, of consecutive frames.

    Returns (d_top, d_bottom), each of length n - 1: d_top[j] compares frames j and j+1.
    Streams: only two frames are held at a time.
    """
    d_top: list[float] = []
    d_bottom: list[float] = []
    previous: np.ndarray | None = None
    for frame in frames:
        frame = np.asarray(frame, dtype=np.float32)
        if previous is not None:
            diff = np.abs(frame - previous)
            d_top.append(float(diff[0::2].mean()))
            d_bottom.append(float(diff[1::2].mean()))
        previous = frame
    return np.asarray(d_top), np.asarray(d_bottom)


def stream_differences(d_top: np.ndarray, d_bottom: np.ndarray, order: FieldOrder) -> np.ndarray:
    """d[k] for the field stream: field 2j is frame j's first field, 2j+1 its second."""
    first, second = (d_top, d_bottom) if order == "tff" else (d_bottom, d_top)
    d = np.empty(2 * len(first))
    d[0::2] = first
    d[1::2] = second
    return d


def cadence_sources(n_fields: int, cadence: Cadence, phase: int = 0) -> np.ndarray:
    """Film frame (0-based, from the first one seen) of each of `n_fields` fields.

    The clip starts `phase` fields into the cadence's cycle.
    """
    counts = np.asarray(cadence.counts)
    cycles = (n_fields + phase) // max(1, counts.sum()) + 2
    tiled = np.tile(counts, cycles)
    ids = np.repeat(np.arange(len(tiled)), tiled)[phase: phase + n_fields]
    return ids - ids[0]


@dataclass(frozen=True)
class Detection:
    """The cadence and phase that explain a field stream, with the evidence."""

    cadence: Cadence
    phase: int
    violations: int
    unexplained: int


def detect(
    d: np.ndarray,
    candidates: Sequence[str | Cadence] = CANDIDATES,
    tolerance: float = 0.0,
) -> Detection:
    """The candidate cadence and phase that best explain the repeat pattern of `d`.

    A candidate predicts the set R of fields k whose k+2 comes from the same film frame;
    the measured zeros are Z = {k : d[k] <= tolerance}. Score = (|R - Z|, |Z - R|),
    lowest first, ties to the earlier candidate and smaller phase.
    """
    n_fields = len(d) + 2
    zeros = d <= tolerance
    best: Detection | None = None
    for candidate in candidates:
        cadence = parse_cadence(candidate) if isinstance(candidate, str) else candidate
        for phase in range(max(1, cadence.fields_per_cycle)):
            src = cadence_sources(n_fields, cadence, phase)
            repeats = src[2:] == src[:-2]
            found = Detection(
                cadence,
                phase,
                violations=int(np.count_nonzero(repeats & ~zeros)),
                unexplained=int(np.count_nonzero(zeros & ~repeats)),
            )
            if best is None or (found.violations, found.unexplained) < (best.violations, best.unexplained):
                best = found
    if best is None:
        raise FrameIOError("no candidate cadence to detect")
    return best


@dataclass(frozen=True)
class Recovered:
    """A film frame to rebuild: its top field from video frame `top_from`, bottom from `bottom_from`."""

    source: int
    top_from: int
    bottom_from: int


def recovery_map(field_sources: Sequence[int], order: FieldOrder) -> list[Recovered]:
    """Where each film frame's two fields are, given the film frame of every field.

    `field_sources[k]` is the film frame of field k (time order); field k is in video
    frame k // 2 with the first parity of `order` when k is even. Film frames are
    returned in increasing order; ones with a single field at either end are dropped.
    """
    parities: tuple[Parity, Parity] = (first_parity(order), second_parity(order))
    found: dict[int, dict[Parity, int]] = {}
    for k, source in enumerate(field_sources):
        found.setdefault(int(source), {}).setdefault(parities[k % 2], k // 2)
    ordered = sorted(found)
    out: list[Recovered] = []
    for i, source in enumerate(ordered):
        where = found[source]
        if "top" in where and "bottom" in where:
            out.append(Recovered(source, where["top"], where["bottom"]))
        elif 0 < i < len(ordered) - 1:
            only = next(iter(where))
            raise FrameIOError(
                f"film frame {source} has only a {only} field (video frame {where[only]}); "
                "this cadence cannot be inverted"
            )
    return out


def detect_pulldown(
    frames: Iterable[np.ndarray],
    count: int,
    order: FieldOrder,
    pattern: str | Cadence | None = None,
    tolerance: float = 0.0,
) -> tuple[list[int], Detection]:
    """Detect the cadence (pattern None: among CANDIDATES) of `count` video frames and the
    source film frame of each of their 2 * count fields. Callers check `violations`."""
    d = stream_differences(*field_differences(frames), order)
    found = detect(d, CANDIDATES if pattern is None else (pattern,), tolerance)
    return [int(s) for s in cadence_sources(2 * count, found.cadence, found.phase)], found


def inverse_frames(
    frames: Sequence[np.ndarray],
    order: FieldOrder,
    pattern: str | Cadence | None = None,
    tolerance: float = 0.0,
) -> tuple[list[np.ndarray], Detection]:
    """In-memory inverse telecine of video frames (each [H, W, ...]); pattern None = detect."""
    sources, found = detect_pulldown(frames, len(frames), order, pattern, tolerance)
    if found.violations:
        raise FrameIOError(
            f"the frames do not follow {found.cadence.name} pulldown: {found.violations} "
            "fields that should repeat differ"
        )
    return [weave_frames(frames[r.top_from], frames[r.bottom_from]) for r in recovery_map(sources, order)], found
