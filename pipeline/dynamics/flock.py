"""Flocks and crowds: Reynolds's boids, vectorised over the agents (docs/seed-motion.md).

One step (fixed dt, the flock's own `step`), every stage over all agents at once:
  neighbours -> the k nearest agents within `neighbour_radius` (scipy cKDTree, O(n log n))
  steer      -> a = responsiveness * (w_sep s_sep + w_ali s_ali + w_coh s_coh + w_goal s_goal
                + w_avoid s_avoid + s_bounds), |a| <= max_accel; every rule s_* is a
                velocity change in m/s (Reynolds's "desired velocity - velocity")
  integrate  -> semi-implicit Euler: v += a dt, speed clamped to [min_speed, max_speed],
                x += v dt
  separate   -> hard constraint: agents closer than `separation` are pushed apart
                symmetrically (k nearest by cKDTree), repeated until none is left (bounded)
  contain    -> agents are pushed out of colliders and back into `bounds`
  record     -> x, v (float32) at every step, or every k-th for big flocks
Between records positions interpolate linearly (the step is small; linear keeps the
separation of two recorded states up to O(dt^2)); the facing direction is the
interpolated velocity. The agents become vertices (each a copy of the agent mesh facing
along its velocity) in the motion stage: pipeline/motion/instances.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.spatial import cKDTree

from ..errors import SimulationError
from ..motion.instances import unit
from .collisions import BoxCollider, Collider, PlaneCollider, SphereCollider

RECORD_BUDGET = 256 * 2**20  # bytes of recorded agent states per flock
MAX_STEPS = 2_000_000  # steps a flock may be asked to take (t_end - start) / step
SEPARATION_PASSES = 8  # most projection passes per step


@dataclass(frozen=True)
class FlockParams:
    """The numbers of one flock (from the scene's `deform: {type: flock}` block)."""

    count: int
    seed: int
    spawn_center: np.ndarray
    spawn_size: np.ndarray
    speed: float
    min_speed: float
    max_speed: float
    max_accel: float
    responsiveness: float
    neighbour_radius: float
    neighbours: int
    separation: float
    separation_range: float
    w_sep: float
    w_ali: float
    w_coh: float
    w_goal: float
    w_avoid: float
    goal: np.ndarray | None
    avoid_distance: float
    look_ahead: float
    bounds: tuple[np.ndarray, np.ndarray] | None
    planar: bool
    up: np.ndarray
    step: float
    start: float

    @classmethod
    def from_spec(cls, spec: Any, epoch: float = 0.0) -> "FlockParams":
        """From a scene `Flock` record; its `start` counts from `epoch`, the scene time of
        the shot's first frame (world.shot_start)."""
        up = np.asarray(spec.up, dtype=np.float64)
        w = spec.weights
        return cls(
            count=int(spec.count),
            seed=int(spec.seed),
            spawn_center=np.asarray(spec.spawn_center, dtype=np.float64),
            spawn_size=np.asarray(spec.spawn_size, dtype=np.float64),
            speed=float(spec.speed),
            min_speed=float(spec.min_speed),
            max_speed=float(spec.max_speed),
            max_accel=float(spec.max_accel),
            responsiveness=float(spec.responsiveness),
            neighbour_radius=float(spec.neighbour_radius),
            neighbours=int(spec.neighbours),
            separation=float(spec.separation),
            separation_range=float(spec.separation_range if spec.separation_range is not None else 2.0 * spec.separation),
            w_sep=float(w.separation),
            w_ali=float(w.alignment),
            w_coh=float(w.cohesion),
            w_goal=float(w.goal),
            w_avoid=float(w.avoid),
            goal=None if spec.goal is None else np.asarray(spec.goal, dtype=np.float64),
            avoid_distance=float(spec.avoid_distance),
            look_ahead=float(spec.look_ahead),
            bounds=None if spec.bounds is None else (np.asarray(spec.bounds.min, dtype=np.float64), np.asarray(spec.bounds.max, dtype=np.float64)),
            planar=bool(spec.planar),
            up=up / np.linalg.norm(up),
            step=float(spec.step),
            start=epoch + float(spec.start),
        )


@dataclass
class FlockTrack:
    """Recorded agent states: times [K] (s), x and v [K, n, 3] (float32)."""

    times: np.ndarray
    x: np.ndarray
    v: np.ndarray

    def at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities [T, n, 3] at `times` (clamped to the record), linear
        between records."""
        t = np.clip(np.atleast_1d(np.asarray(times, dtype=np.float64)), self.times[0], self.times[-1])
        if len(self.times) == 1:
            shape = (t.size,) + self.x.shape[1:]
            return np.broadcast_to(self.x[0], shape).astype(np.float64), np.broadcast_to(self.v[0], shape).astype(np.float64)
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        s = ((t - self.times[k]) / (self.times[k + 1] - self.times[k]))[:, None, None]
        x = (1.0 - s) * self.x[k] + s * self.x[k + 1]
        v = (1.0 - s) * self.v[k] + s * self.v[k + 1]
        return x, v


# --- initial state ------------------------------------------------------------------------


def _tangent(v: np.ndarray, up: np.ndarray) -> np.ndarray:
    """v without its component along `up`."""
    return v - (v @ up)[..., None] * up


def spawn(p: FlockParams) -> tuple[np.ndarray, np.ndarray]:
    """Seeded start positions (uniform in the spawn box) and velocities (speed `speed`,
    uniform directions on the sphere, or in the plane normal to `up` when planar)."""
    rng = np.random.default_rng(p.seed)
    x = p.spawn_center + (rng.random((p.count, 3)) - 0.5) * p.spawn_size
    d = rng.normal(size=(p.count, 3))
    if p.planar:
        d = _tangent(d, p.up)
        x = x - ((x - p.spawn_center) @ p.up)[:, None] * p.up  # on the spawn centre's plane
    n = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), np.array([0.0, 0.0, 1.0]))
    return x, d * p.speed


# --- obstacles ----------------------------------------------------------------------------


def obstacle_distance(col: Collider, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) from points [n, 3] to a collider's surface, and the unit direction
    from the surface towards the point. Colliders the flock cannot see: (inf, 0)."""
    n = len(x)
    if isinstance(col, SphereCollider):
        d = x - col.center
        r = np.linalg.norm(d, axis=1)
        normal = d / np.maximum(r, 1e-12)[:, None]
        return r - col.radius, normal
    if isinstance(col, BoxCollider):
        p = (x - col.center) @ col.rotation  # box frame
        q = np.abs(p) - col.half
        outside = np.maximum(q, 0.0)
        dist_out = np.linalg.norm(outside, axis=1)
        inside_depth = np.minimum(q.max(axis=1), 0.0)
        dist = dist_out + inside_depth  # signed distance of a box
        # direction: the outside vector, or (inside) the axis of least penetration
        axis = np.argmax(q, axis=1)
        n_in = np.zeros_like(p)
        n_in[np.arange(n), axis] = np.sign(p[np.arange(n), axis]) + (p[np.arange(n), axis] == 0)
        n_out = np.sign(p) * outside / np.maximum(dist_out, 1e-12)[:, None]
        local = np.where((dist_out > 0)[:, None], n_out, n_in)
        return dist, local @ col.rotation.T
    if isinstance(col, PlaneCollider):
        rel = x - col.point
        sd = rel @ col.normal
        pu, pv = rel @ col.u, rel @ col.v
        if col.disk_radius is not None:
            inside = pu * pu + pv * pv <= col.disk_radius**2
        else:
            inside = (np.abs(pu) <= col.half_u) & (np.abs(pv) <= col.half_v)
        side = np.where(sd >= 0, 1.0, -1.0)
        dist = np.where(inside, np.abs(sd), np.inf)
        return dist, side[:, None] * col.normal[None, :]
    return np.full(n, np.inf), np.zeros((n, 3))


# --- the step -----------------------------------------------------------------------------


def steering(p: FlockParams, x: np.ndarray, v: np.ndarray, colliders: Sequence[Collider]) -> np.ndarray:
    """The steering acceleration [n, 3] of every agent (the `steer` stage)."""
    n = len(x)
    k = min(p.neighbours + 1, n)
    dist, idx = cKDTree(x).query(x, k=k, distance_upper_bound=p.neighbour_radius)
    dist, idx = np.atleast_2d(dist).reshape(n, k), np.atleast_2d(idx).reshape(n, k)
    valid = (idx < n) & (idx != np.arange(n)[:, None])
    j = np.where(valid, idx, 0)
    count = valid.sum(axis=1)
    has = count > 0
    inv_count = 1.0 / np.maximum(count, 1)
    xj, vj = x[j], v[j]  # [n, k, 3]
    vf = valid[..., None]
    # separation: away from each neighbour inside separation_range, stronger when closer
    d = np.where(valid, dist, np.inf)
    away = x[:, None, :] - xj
    near = valid & (d < p.separation_range)
    push = np.where(near, 1.0 - d / p.separation_range, 0.0)[..., None] * unit(away)
    s_sep = p.max_speed * push.sum(axis=1)
    # alignment: towards the neighbours' mean velocity
    mean_v = (vj * vf).sum(axis=1) * inv_count[:, None]
    s_ali = np.where(has[:, None], mean_v - v, 0.0)
    # cohesion: towards the neighbours' centroid, full speed at the neighbour radius
    centroid = (xj * vf).sum(axis=1) * inv_count[:, None]
    s_coh = np.where(has[:, None], (centroid - x) * (p.max_speed / p.neighbour_radius), 0.0)
    total = p.w_sep * s_sep + p.w_ali * s_ali + p.w_coh * s_coh
    if p.goal is not None and p.w_goal > 0:
        total += p.w_goal * (p.max_speed * unit(p.goal - x) - v)
    if colliders and p.w_avoid > 0:
        # near a surface: straight away from it; where the agent will be in look_ahead
        # seconds: sideways (the part of the surface normal across the heading), so it
        # turns past the obstacle instead of braking in front of it
        ahead = x + v * p.look_ahead
        heading = unit(v)
        s_avoid = np.zeros_like(x)
        for col in colliders:
            dc, nc = obstacle_distance(col, x)
            s_avoid += p.max_speed * np.clip(1.0 - dc / p.avoid_distance, 0.0, 1.0)[:, None] * nc
            dc, nc = obstacle_distance(col, ahead)
            across = nc - np.einsum("ij,ij->i", nc, heading)[:, None] * heading
            s_avoid += p.max_speed * np.clip(1.0 - dc / p.avoid_distance, 0.0, 1.0)[:, None] * unit(across)
        total += p.w_avoid * s_avoid
    if p.bounds is not None:
        lo, hi = p.bounds
        margin = np.minimum(p.avoid_distance, 0.25 * (hi - lo))
        inward = np.clip((lo + margin - x) / margin, 0.0, 1.0) - np.clip((x - (hi - margin)) / margin, 0.0, 1.0)
        total += p.max_speed * inward
    a = p.responsiveness * total
    if p.planar:
        a = _tangent(a, p.up)
    mag = np.linalg.norm(a, axis=1, keepdims=True)
    return a * np.minimum(1.0, p.max_accel / np.maximum(mag, 1e-12))


def separate(x: np.ndarray, separation: float, passes: int = SEPARATION_PASSES, k: int = 8) -> int:
    """Push apart (in place) agents closer than `separation`: each agent moves half the
    overlap away from each of its (at most k) nearest agents inside the separation (the
    other agent of the pair does the same, so a pair ends exactly apart), the mean of
    those moves when there are several (Jacobi); repeated while overlaps remain (at most
    `passes`). A k-nearest table bounds the memory however packed the agents are.
    Returns the number of passes that moved something."""
    n = len(x)
    if n < 2:
        return 0
    k = min(k + 1, n)
    moved = 0
    rows = np.arange(n)[:, None]
    for _ in range(passes):
        dist, idx = cKDTree(x).query(x, k=k, distance_upper_bound=separation * (1.0 - 1e-9))
        dist, idx = dist.reshape(n, k), idx.reshape(n, k)
        near = (idx < n) & (idx != rows)
        if not near.any():
            break
        j = np.where(near, idx, 0)
        d = x[:, None, :] - x[j]
        r = np.where(near, dist, 1.0)
        # coincident agents separate along a fixed, pair-dependent direction (opposite for
        # the two of a pair)
        angle = (np.minimum(rows, j) * 0.618 + np.maximum(rows, j) * 0.382).astype(np.float64)
        sign = np.where(rows < j, 1.0, -1.0)
        fallback = sign[..., None] * np.stack((np.cos(angle), np.zeros_like(angle), np.sin(angle)), axis=-1)
        u = np.where((r > 1e-12)[..., None], d / np.maximum(r, 1e-12)[..., None], fallback)
        # half the overlap, and a hair more so the pair ends just outside
        push = np.where(near, 0.5 * (separation - r) * (1.0 + 1e-6), 0.0)[..., None] * u
        count = near.sum(axis=1)
        x += push.sum(axis=1) / np.maximum(count, 1)[:, None]
        moved += 1
    return moved


def contain(p: FlockParams, x: np.ndarray, v: np.ndarray, colliders: Sequence[Collider]) -> None:
    """Keep agents out of colliders and inside the bounds (in place): position projected
    to the surface, the velocity component into the surface removed."""
    for col in colliders:
        dc, nc = obstacle_distance(col, x)
        inside = dc < 0.0
        if inside.any():
            x[inside] -= dc[inside, None] * nc[inside]
            vn = np.einsum("ij,ij->i", v[inside], nc[inside])
            v[inside] -= np.minimum(vn, 0.0)[:, None] * nc[inside]
    if p.bounds is not None:
        lo, hi = p.bounds
        below, above = x < lo, x > hi
        np.clip(x, lo, hi, out=x)
        v[below] = np.abs(v[below])
        v[above] = -np.abs(v[above])


def flock_step(p: FlockParams, x: np.ndarray, v: np.ndarray, colliders: Sequence[Collider], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One fixed step of every stage but `record`; returns new (x, v)."""
    a = steering(p, x, v, colliders)
    v = v + a * dt
    if p.planar:
        v = _tangent(v, p.up)
    speed = np.linalg.norm(v, axis=1, keepdims=True)
    clamped = np.clip(speed, p.min_speed, p.max_speed)
    v = np.where(speed > 1e-12, v * clamped / np.maximum(speed, 1e-12), v)
    x = x + v * dt
    separate(x, p.separation)
    contain(p, x, v, colliders)
    if not (np.isfinite(x).all() and np.isfinite(v).all()):
        raise SimulationError("flock: a non-finite agent state (check the weights and speeds)")
    return x, v


def simulate_flock(p: FlockParams, colliders: Sequence[Collider], t_start: float, t_end: float, name: str = "flock") -> FlockTrack:
    """Run a flock from t_start to t_end; agents hold their spawn state before `start`."""
    x, v = spawn(p)
    begin = max(t_start, p.start)
    steps = max(0, int(math.ceil((t_end - begin) / p.step - 1e-9)))
    if steps > MAX_STEPS:
        raise SimulationError(f"flock '{name}': {steps} steps of {p.step} s to reach t = {t_end} s exceeds the limit of {MAX_STEPS}")
    stride = max(1, int(math.ceil((steps + 1) * p.count * 24 / RECORD_BUDGET)))
    times, xs, vs = [t_start], [x.astype(np.float32)], [v.astype(np.float32)]
    if begin > t_start:
        times.append(begin)
        xs.append(xs[0])
        vs.append(vs[0])
    for k in range(steps):
        x, v = flock_step(p, x, v, colliders, p.step)
        if (k + 1) % stride == 0 or k == steps - 1:
            times.append(begin + (k + 1) * p.step)
            xs.append(x.astype(np.float32))
            vs.append(v.astype(np.float32))
    return FlockTrack(np.asarray(times), np.stack(xs), np.stack(vs))
