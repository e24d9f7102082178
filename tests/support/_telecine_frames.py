"""Film frames for the telecine tests that encode their own identity: R = film frame index,
G = row, B = column (all exact in half float), so every output field can be traced to its
source frame and rows; and the documented cadence tables."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np

from motion.pipeline.frame_output import write_frame

H, W = 24, 32


def ident(i: int, h: int = H, w: int = W) -> np.ndarray:
    """A frame that encodes its index and each pixel's row and column."""
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., 0] = i
    rgba[..., 1] = np.arange(h)[:, None]
    rgba[..., 2] = np.arange(w)[None, :]
    rgba[..., 3] = 1
    return rgba


def write_seq(folder: Path, n: int, first: int = 1, name: str = "shot", fps: int = 24) -> Path:
    for i in range(n):
        write_frame(folder / f"{name}.{first + i:04d}.exr", ident(i), {"frame": first + i, "spp": 4}, fps=Fraction(fps))
    return folder


# Documented tables (top, bottom) for A B C D = 0 1 2 3, top field first.
TABLES = {
    "3:2": [(0, 0), (1, 1), (1, 2), (2, 3), (3, 3)],
    "2:3:3:2": [(0, 0), (1, 1), (1, 2), (2, 2), (3, 3)],
    "2:2": [(0, 0), (1, 1), (2, 2), (3, 3)],
}
