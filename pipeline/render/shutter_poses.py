"""Baked poses across a frame's shutter, on the host (numpy): the pose at one shutter
fraction, and the N samples the integrator receives for a motion-blur mode.

A baked track holds 1 + N rows: row 0 at the frame's time, rows 1..N spanning the shutter
(`StackedFrame`). The integrator interpolates between the N rows per path at the path's
own time (render/poses.py); here the same interpolation (translation lerp, rotation slerp)
serves the modes that see one instant: `off` (all at the frame's time) and one sub-frame
(all at its shutter fraction).
"""

from __future__ import annotations

import numpy as np

from ..motion.pose import slerp


def resample(t: np.ndarray, q: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose at shutter fraction u from N samples spanning the shutter (lerp + slerp)."""
    n = len(t)
    x = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(np.floor(x)), n - 2)
    f = x - i
    return (1 - f) * t[i] + f * t[i + 1], slerp(q[i], q[i + 1], f)


def pose_at(t: np.ndarray, q: np.ndarray, u: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A stacked track's pose at the frame's time (u None) or at shutter fraction u."""
    return (t[0], q[0]) if u is None else resample(t[1:], q[1:], u)


def across_shutter(t: np.ndarray, q: np.ndarray, n: int, mode: str, u_fixed: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The N samples [N, 3], [N, 4] of a stacked track that the integrator gets: the
    baked ones (stochastic blur), or N copies of one instant: the frame's time for
    `off`, shutter fraction `u_fixed` for one sub-frame."""
    if mode == "off":
        tt, qq = t[0], q[0]
    elif u_fixed is not None:
        tt, qq = resample(t[1:], q[1:], u_fixed)
    else:
        return t[1:], q[1:]
    return np.repeat(np.asarray(tt)[None], n, axis=0), np.repeat(np.asarray(qq)[None], n, axis=0)
