"""The follower of a planned path: a simulated vehicle tracking the path the motion stage
planned (motion/plan.py), run by the dynamics stage and recorded as a FollowerTrack;
plan.follower_pose poses the object it carries."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import SceneError
from .forces import drag

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene


@dataclass
class FollowerTrack:
    """Recorded follower states: times [K], x, v, a [K, 3]; `deviation` [K] its distance
    from the path (m)."""

    times: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    deviation: np.ndarray

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x (cubic Hermite with the recorded velocities), v and a (linear) at `times`."""
        t = np.clip(np.asarray(times, dtype=np.float64), self.times[0], self.times[-1])
        if len(self.times) == 1:
            return (np.broadcast_to(arr[0], (len(t), 3)).copy() for arr in (self.x, self.v, self.a))  # type: ignore[return-value]
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        h = (self.times[k + 1] - self.times[k])[:, None]
        s = ((t - self.times[k]) / h[:, 0])[:, None]
        s2, s3 = s * s, s * s * s
        x = (2 * s3 - 3 * s2 + 1) * self.x[k] + (s3 - 2 * s2 + s) * h * self.v[k] + (-2 * s3 + 3 * s2) * self.x[k + 1] + (s3 - s2) * h * self.v[k + 1]
        v = (1 - s) * self.v[k] + s * self.v[k + 1]
        a = (1 - s) * self.a[k] + s * self.a[k + 1]
        return x, v, a


def simulate_follower(loaded: "LoadedScene", index: int, t_start: float, t_end: float) -> FollowerTrack:
    """Simulate object `index`'s follower from t_start to t_end at the scene's dynamics step:
    m a = m g + hover (-m g) + drag (-1/2 rho Cd A |v| v) + steering, where steering is the
    constant acceleration that brings the predicted position x + v tau onto the path's
    position at t + tau: a_s = 2 (p(t + tau) - x - v tau) / tau^2, at most max_accel
    (linearised: a PD law with kp = 2 / tau^2, kd = 2 / tau, damping ratio 1/sqrt 2, plus
    the path's own acceleration as feed-forward). Semi-implicit Euler. A located error if
    it strays more than `tolerance` from the path."""
    obj = loaded.scene.objects[index]
    spec = obj.motion.follower
    from ..motion.plan import plan_for  # here: planning imports scipy (0.15+ s), which only planned paths need

    path = plan_for(loaded, index)
    d = loaded.scene.dynamics
    dt = float(d.step)
    steps = max(1, int(math.ceil((t_end - t_start) / dt - 1e-9)))
    if steps > 5_000_000:
        raise SceneError([loaded.source.problem(("objects", index, "motion", "follower"), f"{obj.name}: {steps} steps to t = {t_end} s is too many")])
    times = t_start + dt * np.arange(steps + 1)
    tau = spec.look_ahead
    target = path.position(times + tau)  # where the path will be, one look-ahead later
    g = np.asarray(d.gravity, dtype=np.float64)
    m = spec.mass
    x = path.position(np.array([t_start]))[0]
    h0 = 1e-3
    v = (path.position(np.array([t_start + h0])) - path.position(np.array([t_start - h0])))[0] / (2 * h0)
    xs, vs, accs = np.empty((steps + 1, 3)), np.empty((steps + 1, 3)), np.empty((steps + 1, 3))
    mass = np.array([m])
    for k in range(steps + 1):
        steer = 2.0 * (target[k] - x - v * tau) / (tau * tau)
        norm = math.sqrt(float(steer @ steer))
        if norm > spec.max_accel:
            steer *= spec.max_accel / norm
        f_drag = drag(v[None], mass, d.air_density, np.array([spec.cd]), np.array([spec.area]), np.zeros(1), dt)[0]
        a = g + (-g) + f_drag / m + steer  # gravity, hover (carries the weight), drag, steering
        xs[k], vs[k], accs[k] = x, v, a
        if k == steps:
            break
        v = v + a * dt
        x = x + v * dt
    if not np.isfinite(xs).all():
        raise SceneError([loaded.source.problem(("objects", index, "motion", "follower"), f"{obj.name}: the follower's state is not finite")])
    # deviation: distance to the nearest dense path sample (an upper bound of the distance
    # to the path, off by at most half the sample spacing)
    dense = path.samples()
    from scipy.spatial import cKDTree  # here: scipy.spatial costs a process ~0.15 s to import, and only followers need it

    dev, _ = cKDTree(dense).query(xs)
    worst = int(np.argmax(dev))
    if dev[worst] > spec.tolerance:
        raise SceneError([loaded.source.problem(("objects", index, "motion", "follower", "tolerance"),
                         f"{obj.name}: the follower strays {dev[worst]:.3g} m from the planned path at t = {times[worst]:.3f} s "
                         f"(tolerance {spec.tolerance} m): lower the speed or accel, or raise max_accel or the tolerance")])
    return FollowerTrack(times, xs, vs, accs, dev)


