"""The field model: an interlaced frame is two fields of alternate rows (the one home of
field parity: the renderer's `--fields` and telecine both read it here).

The top field is rows 0, 2, 4, ... and the bottom field rows 1, 3, 5, ... (row 0 is the
top of the image). The field order (`tff`: top field first, `bff`: bottom field first)
says which of the two is earlier in time. Every function works on any array whose first
axis is rows ([H, W], [H, W, C]); a field is a strided view, never a copy, and weaving
two fields into a frame is two slice assignments.

>>> import numpy as np
>>> frame = np.arange(6).reshape(6, 1)
>>> top, bottom = split(frame)
>>> top.ravel().tolist(), bottom.ravel().tolist()
([0, 2, 4], [1, 3, 5])
>>> weave(top, bottom).ravel().tolist()
[0, 1, 2, 3, 4, 5]
>>> first_parity("bff"), second_parity("bff")
('bottom', 'top')
>>> parity_of(0, "tff"), parity_of(1, "tff"), parity_of(0, "bff")
('top', 'bottom', 'bottom')
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from .errors import UsageError

if TYPE_CHECKING:  # numpy is imported by the functions that make arrays (the parity helpers need none)
    import numpy as np

Parity = Literal["top", "bottom"]
FieldOrder = Literal["tff", "bff"]
FIELD_ORDERS: tuple[FieldOrder, ...] = ("tff", "bff")

_ROWS: dict[str, slice] = {"top": slice(0, None, 2), "bottom": slice(1, None, 2)}


def check_field_order(order: str) -> FieldOrder:
    """Validate a field order string ('tff' or 'bff'); UsageError otherwise."""
    if order not in FIELD_ORDERS:
        raise UsageError(f"field order must be 'tff' or 'bff', got {order!r}")
    return order  # type: ignore[return-value]


def rows(parity: Parity) -> slice:
    """The row slice of a field: 0::2 for the top field, 1::2 for the bottom field."""
    return _ROWS[parity]


def first_parity(order: FieldOrder) -> Parity:
    """The parity of the temporally first field of each frame."""
    return "top" if order == "tff" else "bottom"


def second_parity(order: FieldOrder) -> Parity:
    """The parity of the temporally second field of each frame."""
    return "bottom" if order == "tff" else "top"


def parity_of(field: int, order: str) -> Parity:
    """The parity of field number `field` of a field sequence: field 2k has the order's
    first parity (tff: top, bff: bottom), 2k + 1 the second."""
    return first_parity(order) if field % 2 == 0 else second_parity(order)  # type: ignore[arg-type]


def row_offset(parity: Parity) -> int:
    """The first row of a field: 0 for the top field, 1 for the bottom (every second row
    from there)."""
    return 0 if parity == "top" else 1


def field(frame: np.ndarray, parity: Parity) -> np.ndarray:
    """One field of a frame, as a view (rows of the given parity)."""
    return frame[_ROWS[parity]]


def split(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(top, bottom) fields of a frame, as views."""
    return frame[0::2], frame[1::2]


def weave(top: np.ndarray, bottom: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Interleave a top and a bottom field into one frame.

    A frame of height H has ceil(H/2) top rows and floor(H/2) bottom rows, so the top field
    may be one row taller than the bottom one.
    """
    height = top.shape[0] + bottom.shape[0]
    if top.shape[1:] != bottom.shape[1:] or top.shape[0] - bottom.shape[0] not in (0, 1):
        raise ValueError(f"fields do not pair: top {top.shape}, bottom {bottom.shape}")
    if out is None:
        import numpy as np

        out = np.empty((height,) + top.shape[1:], dtype=np.result_type(top, bottom))
    out[0::2] = top
    out[1::2] = bottom
    return out


def weave_frames(top_from: np.ndarray, bottom_from: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """A frame whose top rows come from `top_from` and bottom rows from `bottom_from`.

    Both inputs are whole frames of the same shape; when they are the same array the result
    is a copy of it.
    """
    if top_from.shape != bottom_from.shape:
        raise ValueError(f"frames differ in shape: {top_from.shape} vs {bottom_from.shape}")
    if out is None:
        import numpy as np

        out = np.empty_like(top_from)
    out[0::2] = top_from[0::2]
    out[1::2] = bottom_from[1::2]
    return out
