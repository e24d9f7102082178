"""Kinematic colliders: colliders whose pose comes from the motion stage (keys, procedural
expressions, planned paths, IK, parents), and bodies seen by particles as moving colliders.

A moving collider is built once in world space at its pose at the run's start (its
*reference* pose, M_ref), as a static collider is. Its motion is the rigid map
G(t) = M(t) M_ref^-1 (world from reference: x = R(t) y + p(t)), sampled on the simulation's
fixed step grid t0 + k step and interpolated between grid points with the translation
linear and the rotation turning at a constant rate, R(t) = exp((t - t_k) w_k) R_k, so
within step k the collider moves as one rigid body with linear velocity
v_k = (p_k+1 - p_k) / step and angular velocity w_k = log(R_k+1 R_k^T) / step; a point x of
it moves at u(x) = v_k + w_k x (x - p(t)). That interpolant is what contacts use (its
velocity is its exact derivative): keyed linear motion is represented exactly.

Contacts are found in the collider's reference frame, where it is still: a body's centre
moves from y0 = G(t)^-1 x0 to y1 = G(t + h)^-1 x1 over the step, and that segment is swept
against the static collider (collisions.py). So a platform rising into a resting ball, or a
bat swung through a ball, is caught whatever the speeds (a relative sweep, linear in the
collider's frame). Impulses use the velocity relative to the surface, v - u(x), and the
collider takes none (infinite mass).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import SceneError
from ..motion.pose import Pose, quat_conj, quat_exp, quat_log, quat_mul, quat_to_matrix

if TYPE_CHECKING:
    from ..scene import LoadedScene

RIGID_TOL = 1e-9  # relative: a collider's G(t) must be a rotation and translation to this


CHUNK = 4096  # grid points of a collider's motion evaluated at once (memory stays bounded)


class ColliderMotion:
    """A moving collider's rigid motion G(t) on the step grid t0 + k step (see the module
    docstring), evaluated `CHUNK` grid points at a time by `sample(times) -> (q [T, 4]
    (w, x, y, z), p [T, 3])`, so a long run never holds every step's pose."""

    def __init__(self, t0: float, step: float, sample: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]) -> None:
        self.t0, self.step = t0, step
        self.sample = sample
        self._lo = -1  # first grid index of the window held
        self._q = self._p = self._R = np.zeros(0)
        self.now = t0  # the time of the state last placed (the guard's energy reads it)
        self.work = 0.0  # J: positive work done on bodies since last read (the guard's budget)
        self.outside_only = False  # only contacts that start outside it (bodies seen by particles)

    def _window(self, k: int) -> None:
        if self._lo <= k and k + 1 < self._lo + len(self._p):
            return
        self._lo = k
        idx = k + np.arange(CHUNK + 1)
        q, p = self.sample(self.t0 + idx * self.step)
        self._q, self._p, self._R = q, p, quat_to_matrix(q)

    def _interval(self, t: float) -> tuple[int, float]:
        k = max(int(np.floor((t - self.t0) / self.step + 1e-9)), 0)
        self._window(k)
        return k, t - (self.t0 + k * self.step)

    def rates(self, t: float, step_start: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(v [3], w [3], p(t) [3]): the linear and angular velocity over the step that
        starts at `step_start` (default: the step containing t; at a grid point, the step
        that starts there) and the origin at t on that step's motion."""
        k, tau = self._interval(t if step_start is None else step_start)
        if step_start is not None:
            tau = t - (self.t0 + k * self.step)
        i = k - self._lo
        v = (self._p[i + 1] - self._p[i]) / self.step
        dq = quat_mul(self._q[i + 1][None], quat_conj(self._q[i][None]))
        w = quat_log(dq)[0] / self.step
        return v, w, self._p[i] + v * tau

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R [3, 3], p [3]) of G(t): world = R y + p."""
        k, tau = self._interval(t)
        i = k - self._lo
        scale = max(1.0, abs(t))
        if abs(tau) <= 1e-12 * scale:
            return self._R[i], self._p[i]
        if abs(tau - self.step) <= 1e-12 * scale:
            return self._R[i + 1], self._p[i + 1]
        v, w, p = self.rates(t)
        turn = quat_to_matrix(quat_exp(w * tau)[None])[0]
        return turn @ self._R[i], p

    def velocity(self, t: float, x: np.ndarray, step_start: float | None = None) -> np.ndarray:
        """u(x) [n, 3]: the velocity (m/s) of the collider's points x [n, 3] at time t, on
        the step that starts at `step_start` (default: the one containing t)."""
        v, w, p = self.rates(t, step_start)
        return v + np.cross(w, x - p)

    def to_reference(self, t: float, x: np.ndarray) -> np.ndarray:
        """Points x [n, 3] (world, time t) in the collider's reference frame: R^T (x - p)."""
        R, p = self.at(t)
        return (x - p) @ R

    def direction_to_world(self, t: float, d: np.ndarray) -> np.ndarray:
        """Directions d [n, 3] of the reference frame at time t, in world space."""
        R, _ = self.at(t)
        return d @ R.T

    def take_work(self) -> float:
        """The positive work (J) done on bodies since the last call; resets it."""
        w, self.work = self.work, 0.0
        return w


def rigid_motion(world_at: Callable[[np.ndarray], Pose], problem: Callable[[float], SceneError], t0: float, step: float) -> ColliderMotion:
    """The ColliderMotion G(t) = M(t) M(t0)^-1 of an object whose world pose at any times
    `world_at(times)` gives; a moving collider keeps its size and shape (`problem(t)`, a
    located error, otherwise: it would need a deforming collider)."""
    from scipy.spatial.transform import Rotation

    ref_inv = np.linalg.inv(world_at(np.array([t0])).matrices()[0])

    def sample(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        G = world_at(times).matrices() @ ref_inv
        R = G[:, :3, :3]
        off = np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3)[None]).max(axis=(1, 2))
        if (off > RIGID_TOL).any():
            raise problem(float(times[int(np.argmax(off > RIGID_TOL))]))
        return Rotation.from_matrix(R).as_quat(scalar_first=True), G[:, :3, 3].copy()

    return ColliderMotion(t0, step, sample)


def kinematic_world_poses(loaded: "LoadedScene", names: set[str], t: np.ndarray) -> dict[str, Pose]:
    """World poses at times t [T] of the objects `names` and their parents, none of which
    may depend on the simulation (validation refuses such a collider): keys, procedural
    motion, planned paths without a follower, parents, and IK chains whose every object is
    kinematic (motion/ik.py, as the motion stage evaluates them)."""
    from dataclasses import replace

    from ..motion.graph import evaluation_order
    from ..motion.local_pose import local_pose, object_base
    from ..motion.pose import compose

    scene = loaded.scene
    by_name = {o.name: (i, o) for i, o in enumerate(scene.objects)}
    need: set[str] = set()
    for name in names:
        node: str | None = name
        while node is not None and node not in need:
            need.add(node)
            node = by_name[node][1].parent
    iks = [c for c in scene.ik if any(n in need for n in (*c.chain, c.target, c.pole) if n is not None)]
    for c in iks:  # their targets and poles (and parents) are evaluated too
        for n in (*c.chain, c.target, c.pole):
            node = n
            while node is not None and node not in need:
                need.add(node)
                node = by_name[node][1].parent
    world: dict[str, Pose] = {}
    local: dict[str, Pose] = {}
    for name in evaluation_order({n: by_name[n][1].parent for n in need}):
        i, obj = by_name[name]
        if obj.motion.type == "plan":
            from ..motion import plan

            world[name] = plan.kinematic_pose(loaded, i, t)
            continue
        lp = local_pose(loaded, ("objects", i), obj.motion, object_base(obj), t, {})
        pose = Pose(lp.translation, lp.rotation, lp.scale)
        local[name] = pose
        world[name] = compose(world[obj.parent], pose) if obj.parent is not None else pose
    if iks:
        from ..motion.ik import apply_ik

        sub = replace(loaded, scene=scene.model_copy(update={"ik": iks}))
        apply_ik(sub, t, world, local)
    return world
