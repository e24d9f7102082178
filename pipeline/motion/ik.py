"""Inverse kinematics on chains of parented objects (docs/seed-motion.md, "Inverse kinematics").

Where it runs: evaluate.py computes every object's keyed local pose and the world poses;
then each `ik:` constraint in order reads its target (and pole) world position, solves its
chain's joint rotations, blends them with the keyed ones by its weight, and the world poses
of the chain and everything parented under it are composed again. So IK sees the keyed pose
of its chain and acts before parenting is resolved for the chain's children.

Solvers (vectorised over the T times; the only loops are over the joints and iterations):
* two-bone (analytic): root a, middle b, effector c with bone lengths l1 = |b - a|,
  l2 = |c - b| from the keyed pose. d = |target - a| clamped to [|l1 - l2|, l1 + l2];
  the middle joint's angle from the law of cosines, cos A = (l1^2 + d^2 - l2^2) / (2 l1 d);
  b' = a + l1 (cos A u + sin A w), u towards the target, w the unit part of (pole - a)
  across u (the bend side). The root turns its frame (bone direction, bend-plane normal)
  onto the new one; the middle joint then turns about the new bend-plane normal only. A
  reachable target is met exactly; an unreachable one is pointed at, fully stretched
  (or folded), never NaN.
* ccd (cyclic coordinate descent): from the last joint to the root, each turns by the
  shortest arc that takes (effector - joint) onto (target - joint), then is limited: a
  hinge keeps only the twist about its axis (swing-twist split) clamped to [min, max]; a
  ball joint's rotation away from its keyed local rotation is clamped to `cone` degrees.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
from scipy.spatial.transform import Rotation

from ..scene.motion_schema import IKConstraint
from .graph import evaluation_order
from .pose import Pose, compose, quat_conj, quat_mul, quat_normalize, quat_rotate, slerp

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


# --- small vector helpers ------------------------------------------------------------------


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit vectors, lengths) [T, 3], [T]; zero vectors stay zero."""
    n = np.linalg.norm(v, axis=-1)
    return v / np.maximum(n, 1e-300)[..., None], n


def _any_perpendicular(u: np.ndarray) -> np.ndarray:
    ref = np.where((np.abs(u[..., 0]) < 0.9)[..., None], np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    return _unit(np.cross(u, ref))[0]


def shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unit quaternions [T, 4] of the smallest rotation taking direction a onto b
    (q = normalise(1 + a.b, a x b) for unit a, b; half a turn about a perpendicular when
    they are opposite; identity where either is zero)."""
    ua, na = _unit(a)
    ub, nb = _unit(b)
    dot = np.einsum("ij,ij->i", ua, ub)
    q = np.concatenate(((1.0 + dot)[:, None], np.cross(ua, ub)), axis=1)
    opposite = dot < -1.0 + 1e-12
    if opposite.any():
        q[opposite] = np.concatenate((np.zeros((int(opposite.sum()), 1)), _any_perpendicular(ua[opposite])), axis=1)
    q[(na < 1e-12) | (nb < 1e-12)] = IDENTITY
    return quat_normalize(q)


def _frame_quat(e1: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotation [T, 4] whose columns are (e1, n, e1 x n) (orthonormal inputs)."""
    m = np.stack((e1, n, np.cross(e1, n)), axis=-1)
    return Rotation.from_matrix(m).as_quat(scalar_first=True)


# --- forward kinematics -------------------------------------------------------------------


def chain_world(base: Pose, locals_: list[Pose]) -> list[Pose]:
    """World poses of the chain's joints from the root's parent pose and their locals."""
    out = []
    world = base
    for local in locals_:
        world = compose(world, local)
        out.append(world)
    return out


def _with_rotation(p: Pose, q: np.ndarray) -> Pose:
    return p._replace(rotation=q)


def _local_rotation(parent_world: np.ndarray, world: np.ndarray) -> np.ndarray:
    """parent_from_joint rotation from world rotations: conj(R_parent) R_joint."""
    return quat_normalize(quat_mul(quat_conj(parent_world), world))


# --- the solvers --------------------------------------------------------------------------


def solve_two_bone(base: Pose, locals_: list[Pose], target: np.ndarray, pole: np.ndarray | None) -> list[np.ndarray]:
    """New local rotations of the root and middle joints ([T, 4] each) so the effector
    (the third joint's origin) reaches `target` [T, 3]; `pole` [T, 3] picks the bend side."""
    w0, w1, w2 = chain_world(base, locals_)
    a, b, c = w0.translation, w1.translation, w2.translation
    l1 = np.linalg.norm(b - a, axis=1)
    l2 = np.linalg.norm(c - b, axis=1)
    u, d = _unit(target - a)
    keep = d < 1e-12  # target on the root: keep the current direction
    u = np.where(keep[:, None], _unit(c - a)[0], u)
    u = np.where((np.linalg.norm(u, axis=1) < 0.5)[:, None], _unit(b - a)[0], u)
    d = np.clip(d, np.abs(l1 - l2), l1 + l2)
    # the bend side: the pole (or the keyed middle joint) across the root-target line
    side_from = (pole - a) if pole is not None else (b - a)
    w = side_from - np.einsum("ij,ij->i", side_from, u)[:, None] * u
    w, wn = _unit(w)
    fallback = b - a - np.einsum("ij,ij->i", b - a, u)[:, None] * u
    fallback, fn = _unit(fallback)
    w = np.where((wn > 1e-9)[:, None], w, np.where((fn > 1e-9)[:, None], fallback, _any_perpendicular(u)))
    # law of cosines at the root
    cos_a = np.clip((l1 * l1 + d * d - l2 * l2) / np.maximum(2.0 * l1 * d, 1e-300), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a * cos_a)
    b_new = a + l1[:, None] * (cos_a[:, None] * u + sin_a[:, None] * w)
    c_new = a + d[:, None] * u
    # root: turn the frame (bone, bend-plane normal) onto the new one
    e1_old = _unit(b - a)[0]
    n_old, nn = _unit(np.cross(b - a, c - b))
    # (b' - a) x (c' - b') = -l1 d sin A (u x w): the same sense as the keyed n_old
    n_new = _unit(np.cross(w, u))[0]
    straight = nn < 1e-9 * np.maximum(l1 * l2, 1e-300)
    if straight.any():  # a straight keyed limb: its bend plane is the one it is about to bend in
        proj = n_new[straight] - np.einsum("ij,ij->i", n_new[straight], e1_old[straight])[:, None] * e1_old[straight]
        proj, pn = _unit(proj)
        n_old[straight] = np.where((pn > 1e-9)[:, None], proj, _any_perpendicular(e1_old[straight]))
    # orthogonal to their bones (they are, up to rounding)
    n_old = _unit(n_old - np.einsum("ij,ij->i", n_old, e1_old)[:, None] * e1_old)[0]
    e1_new = _unit(b_new - a)[0]
    n_new = _unit(n_new - np.einsum("ij,ij->i", n_new, e1_new)[:, None] * e1_new)[0]
    delta_root = quat_mul(_frame_quat(e1_new, n_new), quat_conj(_frame_quat(e1_old, n_old)))
    root_world = quat_normalize(quat_mul(delta_root, w0.rotation))
    # middle: after the root turned, the effector is at a + delta_root (c - a); turn about b_new
    c_moved = a + quat_rotate(delta_root, c - a)
    delta_mid = shortest_arc(c_moved - b_new, c_new - b_new)
    mid_world = quat_normalize(quat_mul(delta_mid, quat_mul(delta_root, w1.rotation)))
    return [_local_rotation(base.rotation, root_world), _local_rotation(root_world, mid_world)]


def _limit(q_rel: np.ndarray, limit: Any) -> np.ndarray:
    """Clamp a rotation relative to the keyed local rotation to the joint's limit."""
    if limit.axis is not None:
        axis = np.asarray(limit.axis, dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        # swing-twist: the twist about `axis` is normalise(w, (v.axis) axis)
        proj = q_rel[:, 1:] @ axis
        angle = 2.0 * np.arctan2(proj, q_rel[:, 0])
        angle = (angle + np.pi) % (2 * np.pi) - np.pi
        angle = np.clip(angle, np.radians(limit.min), np.radians(limit.max))
        return np.concatenate((np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis), axis=1)
    q = np.where((q_rel[:, :1] < 0), -q_rel, q_rel)
    angle = 2.0 * np.arccos(np.clip(q[:, 0], -1.0, 1.0))
    cone = np.radians(limit.cone)
    over = angle > cone
    if over.any():
        axis = _unit(q[over, 1:])[0]
        q = q.copy()
        q[over] = np.concatenate((np.cos(cone / 2) * np.ones((int(over.sum()), 1)), np.sin(cone / 2) * axis), axis=1)
    return q


def solve_ccd(base: Pose, locals_: list[Pose], target: np.ndarray, limits: Mapping[int, Any], iterations: int, tolerance: float) -> list[np.ndarray]:
    """New local rotations of every joint but the effector ([T, 4] each) by cyclic
    coordinate descent with joint limits."""
    keyed = [p.rotation for p in locals_]
    rot = [p.rotation.copy() for p in locals_]
    n = len(locals_)
    for _ in range(iterations):
        for j in range(n - 2, -1, -1):
            world = chain_world(base, [_with_rotation(p, r) for p, r in zip(locals_, rot)])
            joint, effector = world[j].translation, world[-1].translation
            delta = shortest_arc(effector - joint, target - joint)
            new_world = quat_mul(delta, world[j].rotation)
            parent = base.rotation if j == 0 else world[j - 1].rotation
            local = _local_rotation(parent, new_world)
            if j in limits:
                rel = _limit(quat_normalize(quat_mul(quat_conj(keyed[j]), local)), limits[j])
                local = quat_normalize(quat_mul(keyed[j], rel))
            rot[j] = local
        world = chain_world(base, [_with_rotation(p, r) for p, r in zip(locals_, rot)])
        if np.linalg.norm(world[-1].translation - target, axis=1).max() <= tolerance:
            break
    return rot[:-1]


# --- the scene stage ----------------------------------------------------------------------


def _weights(loaded: "LoadedScene", c: IKConstraint, t: np.ndarray) -> np.ndarray:
    if not isinstance(c.weight, list):
        return np.full(len(t), float(c.weight))
    seconds = 1.0 if c.time_unit == "seconds" else float(1 / loaded.scene.timeline.rate)
    times = np.array([k.time for k in c.weight]) * seconds
    values = np.array([k.value for k in c.weight])
    return np.clip(np.interp(t, times, values), 0.0, 1.0)  # linear between keys, held outside


MIN_BONE_LENGTH = 1e-9  # m: a shorter bone has no direction to turn


def apply_ik(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose], local: dict[str, Pose]) -> None:
    """Solve every `ik:` constraint in order, in place on `world` (and `local`): each
    chain's joints get their solved rotations blended with the keyed ones, then the
    chain and everything under it is composed again."""
    scene = loaded.scene
    parents = {o.name: o.parent for o in scene.objects}
    order = evaluation_order(parents)
    for k_ik, c in enumerate(scene.ik):
        chain = c.chain
        for a, b in zip(chain, chain[1:]):
            length = np.linalg.norm(world[b].translation - world[a].translation, axis=1)
            if (length < MIN_BONE_LENGTH).any():
                from ..errors import SceneError

                when = float(t[int(np.argmax(length < MIN_BONE_LENGTH))])
                raise SceneError([loaded.source.problem(("ik", k_ik, "chain"), f"the bone {a} -> {b} has no length at t = {when:.6g} s "
                                                        f"({b} sits at {a}'s origin): IK turns bones, so each needs a length (translate {b} away from {a})")])
        root_parent = parents[chain[0]]
        count = len(t)
        base = world[root_parent] if root_parent is not None else Pose(np.zeros((count, 3)), np.tile(IDENTITY, (count, 1)), np.ones((count, 3)))
        locals_ = [local[name] for name in chain]
        target = world[c.target].translation
        effector_world_rot = world[chain[-1]].rotation
        if c.solver == "two-bone":
            pole = world[c.pole].translation if c.pole is not None else None
            solved = solve_two_bone(base, locals_, target, pole)
        else:
            index = {name: k for k, name in enumerate(chain)}
            limits = {index[lim.joint]: lim for lim in c.limits}
            solved = solve_ccd(base, locals_, target, limits, c.iterations, c.tolerance)
        w = _weights(loaded, c, t)
        for name, q in zip(chain[:-1], solved):
            keyed = local[name]
            local[name] = _with_rotation(keyed, slerp(keyed.rotation, q, w))
        if c.keep_effector_rotation:
            posed = chain_world(base, [local[name] for name in chain[:-1]])
            flat = _local_rotation(posed[-1].rotation, effector_world_rot)
            keyed = local[chain[-1]]
            local[chain[-1]] = _with_rotation(keyed, slerp(keyed.rotation, flat, w))
        # compose the chain and its descendants again, parents first
        moved = set(chain)
        for name in order:
            parent = parents[name]
            if name in moved or (parent is not None and parent in moved):
                moved.add(name)
                world[name] = compose(world[parent], local[name]) if parent is not None else local[name]
