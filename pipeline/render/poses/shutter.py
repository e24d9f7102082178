"""Baked poses across a frame's shutter, on the host (numpy): the pose at one shutter
fraction, and the N samples the integrator receives for a motion-blur mode.

A baked track holds 1 + N rows: row 0 at the frame's time, rows 1..N spanning the shutter
(`StackedFrame`). The integrator interpolates between the N rows per path at the path's
own time (render/poses/kernel.py); here the same interpolation (translation lerp, rotation slerp)
serves the modes that see one instant: `off` (all at the frame's time) and one sub-frame
(all at its shutter fraction).
"""

from __future__ import annotations

import numpy as np

from ...motion.pose import slerp


def resample(t: np.ndarray, q: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose at shutter fraction u from N samples spanning the shutter (lerp + slerp):
    t [..., N, 3], q [..., N, 4] (one track, or a stack of them) -> [..., 3], [..., 4]."""
    n = t.shape[-2]
    x = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(np.floor(x)), n - 2)
    f = x - i
    return (1 - f) * t[..., i, :] + f * t[..., i + 1, :], slerp(q[..., i, :], q[..., i + 1, :], f)


def pose_at(t: np.ndarray, q: np.ndarray, u: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A stacked track's pose at the frame's time (u None) or at shutter fraction u."""
    return (t[0], q[0]) if u is None else resample(t[1:], q[1:], u)


def across_shutter(t: np.ndarray, q: np.ndarray, n: int, mode: str, u_fixed: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The N samples [..., N, 3], [..., N, 4] of a stacked track (t [..., 1+N, 3], q
    [..., 1+N, 4]: one, or every mover's at once) that the integrator gets: the baked ones
    (stochastic blur), or N copies of one instant: the frame's time for `off`, shutter
    fraction `u_fixed` for one sub-frame."""
    if mode == "off":
        tt, qq = t[..., 0, :], q[..., 0, :]
    elif u_fixed is not None:
        tt, qq = resample(t[..., 1:, :], q[..., 1:, :], u_fixed)
    else:
        return t[..., 1:, :], q[..., 1:, :]
    return (np.repeat(np.asarray(tt)[..., None, :], n, axis=-2), np.repeat(np.asarray(qq)[..., None, :], n, axis=-2))


def particles_at(positions: np.ndarray, alive: np.ndarray, u: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A particle system's centres [P, 3] and alive flags [P] at the frame's time (u None)
    or at shutter fraction u, from its stacked track (positions [1+N, P, 3], alive
    [1+N, P]): centres lerped between the samples around u, alive as at the nearer one
    (the kernel's `Movers.particle`, for one instant)."""
    if u is None:
        return positions[0], alive[0]
    n = len(positions) - 1
    x = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(np.floor(x)), max(n - 2, 0))
    f = x - i
    p = (1 - f) * positions[1 + i] + f * positions[min(2 + i, n)]
    return p, alive[1 + i] if f < 0.5 else alive[min(2 + i, n)]


def particles_across_shutter(positions: np.ndarray, alive: np.ndarray, n: int, mode: str, u_fixed: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The N samples of a particle system's stacked track (positions [1+N, P, 3], alive
    [1+N, P]) that the integrator gets, as [P, N, 3] and [P, N]: the baked ones, or N
    copies of one instant (the frame's time for `off`, shutter fraction `u_fixed` for one
    sub-frame: `particles_at`)."""
    if mode != "off" and u_fixed is None:
        return np.swapaxes(positions[1:], 0, 1), np.swapaxes(alive[1:], 0, 1)
    p, a = particles_at(positions, alive, None if mode == "off" else u_fixed)
    return np.repeat(np.asarray(p)[:, None], n, axis=1), np.repeat(np.asarray(a)[:, None], n, axis=1)
