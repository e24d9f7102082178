"""The recorded track of one simulated group: states at record times, sampled at any time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.pose import slerp


@dataclass
class Track:
    """Recorded states of one group: times [K]; x, v [K, n, 3]; q [K, n, 4] (rigid);
    contact [K, n] (a contact happened between record k-1 and k); energies [K] (J)."""

    times: np.ndarray
    x: np.ndarray
    v: np.ndarray
    q: np.ndarray | None
    contact: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    impacts: np.ndarray  # [k, 7]: time, body, speed (m/s), other (collider index or -1 - body), centre x, y, z
    kinetic_each: np.ndarray | None = None  # [K, n] per body (body groups only), J
    potential_each: np.ndarray | None = None  # [K, n] per body, gravity (zero at x_ref) + buoyancy, J

    def interpolate(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Positions (and orientations) at `times` ([T] or [T, n], clamped to the record).

        Cubic Hermite with the recorded velocities (exact for constant acceleration);
        linear over intervals that contain a contact (the path bends there, and a
        straight line between two non-penetrating points stays out of a plane); slerp for
        orientations."""
        K, n = self.x.shape[:2]
        t = np.asarray(times, dtype=np.float64)
        if t.ndim == 1:
            t = np.broadcast_to(t[:, None], (t.size, n))
        t = np.clip(t, self.times[0], self.times[-1])
        cols = np.broadcast_to(np.arange(n)[None, :], t.shape)
        if K == 1:
            x = np.broadcast_to(self.x[0], t.shape + (3,)).astype(np.float64)
            q = None if self.q is None else np.broadcast_to(self.q[0], t.shape + (4,)).copy()
            return x, q
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, K - 2)
        h = (self.times[k + 1] - self.times[k])[..., None]
        s = ((t - self.times[k]) / h[..., 0])[..., None]
        x0, x1 = self.x[k, cols].astype(np.float64), self.x[k + 1, cols].astype(np.float64)
        v0, v1 = self.v[k, cols].astype(np.float64), self.v[k + 1, cols].astype(np.float64)
        s2, s3 = s * s, s * s * s
        hermite = (2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * x1 + (s3 - s2) * h * v1
        linear = (1 - s) * x0 + s * x1
        x = np.where(self.contact[k + 1, cols][..., None], linear, hermite)
        q = None if self.q is None else slerp(self.q[k, cols], self.q[k + 1, cols], s[..., 0])
        return x, q
