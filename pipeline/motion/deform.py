"""Deformation: blend shapes and linear blend skinning (object-space vertices over time)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .pose import Pose

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene


def deformed_vertices(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose]) -> dict[str, np.ndarray]:
    """Object-space vertices [T, V, 3] of every deforming object."""
    return {}
