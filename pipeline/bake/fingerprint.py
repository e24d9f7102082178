"""One digest of baked frames (the motion hash `--resume` compares), walking every field
of the records generically: a field added to `BakedFrame` or `SceneMotion` is covered
without touching this file."""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Any, Iterator, Sequence

import numpy as np

from .records import BakedFrame


def leaves(value: Any, key: str = "") -> Iterator[tuple[str, np.ndarray]]:
    """Every number of `value` as (path, float64 array): dataclasses field by field, named
    tuples by name, dicts in sorted key order, sequences of records by index; numbers,
    tuples of numbers and arrays are leaves; None is skipped."""
    if value is None:
        return
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from leaves(getattr(value, f.name), f"{key}/{f.name}")
    elif isinstance(value, tuple) and hasattr(value, "_fields"):
        for name in value._fields:
            yield from leaves(getattr(value, name), f"{key}/{name}")
    elif isinstance(value, dict):
        for k in sorted(value):
            yield from leaves(value[k], f"{key}/{k}")
    elif isinstance(value, (list, tuple)) and value and not isinstance(value[0], (int, float, np.number)):
        for i, v in enumerate(value):
            yield from leaves(v, f"{key}/{i}")
    else:
        yield key, np.ascontiguousarray(value, dtype=np.float64)


def fingerprint(frames: Sequence[BakedFrame]) -> str:
    """A stable SHA-256 digest (hex) of the frames: every leaf's path, shape and float64
    bytes, so any change to anything that animates (objects, camera and its scalars,
    lights and their scalars, vertices, particles, times) changes it."""
    h = hashlib.sha256()
    for frame in frames:
        for key, arr in leaves(frame):
            h.update(key.encode())
            h.update(repr(arr.shape).encode())
            h.update(arr.tobytes())
    return h.hexdigest()
