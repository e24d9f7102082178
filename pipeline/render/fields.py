"""Rendering one field (`motion render --fields`): field 2k has the field order's first
parity, 2k + 1 the second; while a field renders, the motion_path integrator draws only
its rows (the film's FIELD_ROWS, render/film.py), and the field's rows are what is written.

>>> parity_of(0, "tff"), parity_of(1, "tff"), parity_of(0, "bff")
('top', 'bottom', 'bottom')
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator, Literal

import numpy as np

Parity = Literal["top", "bottom"]


def parity_of(field: int, order: str) -> Parity:
    """Field 2k has the order's first parity (tff: top, bff: bottom), 2k + 1 the second
    (the field model: telecine/fields.py)."""
    first_is_top = order == "tff"
    return "top" if (field % 2 == 0) == first_is_top else "bottom"


@contextmanager
def rendering_field(parity: Parity) -> Iterator[None]:
    """While inside, the motion_path integrator draws only the rows of `parity` (top:
    0, 2, 4 ...; bottom: 1, 3, 5 ...) and returns an image of those rows."""
    from . import film

    before = film.FIELD_ROWS
    film.FIELD_ROWS = (0 if parity == "top" else 1, 2)
    try:
        yield
    finally:
        film.FIELD_ROWS = before


def field_rows(image: np.ndarray, parity: Parity, height: int) -> np.ndarray:
    """The field's rows of a renderer's image: already the field (the integrator drew only
    its rows) or a full frame (the scalar fallback renders every row: take its rows)."""
    if image.shape[0] == height:
        return image[0 if parity == "top" else 1 :: 2]
    return image
