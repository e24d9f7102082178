"""Frames written (pipeline/frame_output.py): a half-float frame clamps what a half cannot hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def test_half_float_frames_clamp_what_a_half_cannot_hold(tmp_path: Path) -> None:
    """A glint brighter than 65504 (a sun's specular) wrote inf pixels in a half EXR."""
    from motion.pipeline.frame_output import read_frame, write_frame

    rgba = np.ones((4, 4, 4), np.float32)
    rgba[1, 2, :3] = 1e6
    write_frame(tmp_path / "f.exr", rgba, {"frame": 0})
    back = read_frame(tmp_path / "f.exr")
    assert np.isfinite(back.rgba).all() and back.rgba[1, 2, 0] == 65504 and back.meta["clamped_pixels"] == 1
