"""Bake: the evaluated motion of each frame, at its time and across its shutter, and the
data contract from bake to worker (docs/bake-format.md).

- `records`: `BakedFrame` (what a worker renders: `at_frame` and `across_shutter`
  SceneMotions, named) and `BakedMotion` (a bake).
- `timing`: each frame's sample times and the one simulation time range.
- `baking`: `bake(loaded, frames)` and `evaluate_frames`.
- `file_format`: `write_baked` and `read_baked`, the one writer and the one reader of bake files.
- `checks`: finite values, unit rotations, the particle budget.

The digest of a frame's baked motion (the half of a frame's identity that is motion) lives
with the rest of the frame's identity, in identity/motion_digest.py.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..errors import BakeFileError, FrameNotBakedError
from ..lazy import lazy_names

if TYPE_CHECKING:
    from .baking import bake, evaluate_frames
    from .checks import check_motion, motion_problems, pose_problem, scalar_problem
    from .file_format import FORMAT, VERSION, read_baked, write_baked
    from .records import BakedFrame, BakedFrames, BakedMotion, by_number, summary
    from .timing import sample_seconds, simulate_for, simulation_range

# each public name -> the module of this package that defines it, imported on first use: a
# rerun that bakes nothing reads bake/keep.py without the bake's numeric modules
_HOMES = {
    **dict.fromkeys(("check_motion", "motion_problems", "pose_problem", "scalar_problem"), "checks"),
    **dict.fromkeys(("bake", "evaluate_frames"), "baking"),
    **dict.fromkeys(("FORMAT", "VERSION", "read_baked", "write_baked"), "file_format"),
    **dict.fromkeys(("BakedFrame", "BakedFrames", "BakedMotion", "by_number", "summary"), "records"),
    **dict.fromkeys(("sample_seconds", "simulate_for", "simulation_range"), "timing"),
}

__getattr__ = lazy_names(__name__, _HOMES)

__all__ = [
    "FORMAT",
    "VERSION",
    "BakeFileError",
    "BakedFrame",
    "BakedFrames",
    "BakedMotion",
    "FrameNotBakedError",
    "bake",
    "by_number",
    "check_motion",
    "evaluate_frames",
    "sample_seconds",
    "motion_problems",
    "pose_problem",
    "read_baked",
    "scalar_problem",
    "simulate_for",
    "simulation_range",
    "summary",
    "write_baked",
]
