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

from ..errors import BakeFileError, FrameNotBakedError
from .checks import check_motion, motion_problems, pose_problem, scalar_problem
from .baking import bake, evaluate_frames
from .file_format import FORMAT, VERSION, read_baked, write_baked
from .records import BakedFrame, BakedFrames, BakedMotion, by_number, summary
from .timing import sample_seconds, simulate_for, simulation_range

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
