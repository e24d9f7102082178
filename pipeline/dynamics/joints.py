"""Joints between two bodies or a body and the world: pin (ball and socket), hinge (an axis,
optional angle limits), distance (a rigid rod) and rope (a maximum length, slack below it),
each with an optional breaking force.

How they are solved (the `constrain` stage, after `collide`, whatever the integrator):
the integrator advances the bodies freely over the step, then the joints are projected,
first on positions, then on velocities (the SHAKE/RATTLE split of constrained dynamics,
with orthogonal projections):

1. Positions. Each constraint C(x, q) = 0 (or <= 0 for a rope, and for a hinge's limits)
   is moved back onto its manifold along its gradient, weighted by the inverse masses:
   for a scalar C with unit direction n at the anchors (lever r from each centre of mass)
   the generalised inverse mass is w = sum 1/m + (r x n) . I^-1 (r x n), the correction
   dlambda = -C / w, and each body moves by dlambda n / m and turns by I^-1 (r x n) dlambda
   (zero compliance XPBD). A pin is the distance-0 case along its error vector; a hinge also
   turns its two axes together by the angle between them (w = e . I_a^-1 e + e . I_b^-1 e
   about e = u_a x u_b / |u_a x u_b|), and clamps the angle about the axis to its limits.
2. Velocities. The anchors' relative velocity is removed by an impulse: a pin solves the
   3 x 3 system K lambda = -dv, K = sum (1/m 1 - [r]x I^-1 [r]x); a rod its component along
   the rod (1 x 1); a taut rope only a separating component (it pulls, never pushes); a
   hinge also the relative angular velocity across its axis (2 x 2 in a basis
   perpendicular to it), and at a limit the part that would pass it.

Both passes are Jacobi over all joints at once (vectorised), each body's correction
divided by the number of joints on it, repeated until a pass finds nothing left (at most
`JOINT_ITERATIONS` times; a rod or a pin to the world converges in one or two passes). The velocity impulse over the step gives each joint's force,
|lambda| / h: past its `break_force` the joint breaks (from that step on). The projection
removes energy, never adds it (each step moves the state to the nearest point of the
constraint manifold in the mass metric), so every integrator stays stable; the drift
left is the rounding of the projection (docs/dynamics.md has the figures).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.pose import quat_exp, quat_mul, quat_normalize, quat_to_matrix
from .forces import cross
from .rigid import inverse_inertia_world

PIN, HINGE, DISTANCE, ROPE = 0, 1, 2, 3
KINDS = {"pin": PIN, "hinge": HINGE, "distance": DISTANCE, "rope": ROPE}
JOINT_ITERATIONS = 32  # Jacobi passes at most, each of positions and velocities
POSITION_TOL = 1e-13  # relative to the coordinates: a pass that finds less has converged
VELOCITY_TOL = 1e-12  # m/s, rad/s
WORLD = -1


@dataclass
class JointSet:
    """The joints of a body group, one row each: bodies a, b (b = WORLD: the world), kind,
    anchors in each body's frame (in world space for the world), hinge axes in each frame,
    a reference direction across the axis in each frame (the hinge angle's zero), rod or
    rope length (m), angle limits (rad; -inf, inf: none), breaking force (N; inf: none),
    and which joints still hold."""

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    anchor_a: np.ndarray
    anchor_b: np.ndarray
    axis_a: np.ndarray
    axis_b: np.ndarray
    ref_a: np.ndarray
    ref_b: np.ndarray
    length: np.ndarray
    limits: np.ndarray
    break_force: np.ndarray
    alive: np.ndarray

    @property
    def count(self) -> int:
        """Number of joints."""
        return int(self.a.size)


def _frame_vectors(q: np.ndarray, which: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Vectors `local` [J, 3] fixed in the bodies `which` (WORLD: already world), in world space."""
    out = local.copy()
    body = which >= 0
    if body.any():
        out[body] = np.einsum("jik,jk->ji", quat_to_matrix(quat_normalize(q[which[body]])), local[body])
    return out


class _Bodies:
    """The two sides of every joint: inverse masses and world inverse inertias (0 for the
    world, pinned and held bodies), and each body's share (1 / joints on it)."""

    def __init__(self, joints: JointSet, x: np.ndarray, q: np.ndarray, inv_mass: np.ndarray, inv_inertia: np.ndarray, live: np.ndarray) -> None:
        n = len(x)
        self.inv_I = inverse_inertia_world(q, inv_inertia) if len(x) else np.zeros((0, 3, 3))
        a, b = joints.a[live], joints.b[live]
        world = b < 0
        bb = np.where(world, 0, b)
        self.a, self.b, self.world = a, bb, world
        self.ma = inv_mass[a]
        self.mb = np.where(world, 0.0, inv_mass[bb])
        self.Ia = self.inv_I[a]
        self.Ib = np.where(world[:, None, None], 0.0, self.inv_I[bb])
        count = np.bincount(a, minlength=n) + np.bincount(bb[~world], minlength=n)
        self.share_a = 1.0 / np.maximum(count[a], 1)
        self.share_b = 1.0 / np.maximum(count[bb], 1)


def _gen_inverse_mass(s: _Bodies, ra: np.ndarray, rb: np.ndarray, n: np.ndarray) -> np.ndarray:
    """w = 1/m_a + 1/m_b + (r_a x n) . I_a^-1 (r_a x n) + (r_b x n) . I_b^-1 (r_b x n)."""
    ca, cb = cross(ra, n), cross(rb, n)
    return s.ma + s.mb + np.einsum("ji,jik,jk->j", ca, s.Ia, ca) + np.einsum("ji,jik,jk->j", cb, s.Ib, cb)


def _apply_linear(s: _Bodies, x: np.ndarray, q: np.ndarray, ra: np.ndarray, rb: np.ndarray, p: np.ndarray) -> None:
    """Position step: the generalised displacement p [J, 3] (an impulse-like vector) moves
    a by +p / m_a and turns it by I_a^-1 (r_a x p); b the opposite."""
    np.add.at(x, s.a, (s.share_a * s.ma)[:, None] * p)
    np.add.at(x, s.b, -(s.share_b * s.mb)[:, None] * p)
    _turn(s, q, np.einsum("jik,jk->ji", s.Ia, cross(ra, p)) * s.share_a[:, None], -np.einsum("jik,jk->ji", s.Ib, cross(rb, p)) * s.share_b[:, None])


def _turn(s: _Bodies, q: np.ndarray, da: np.ndarray, db: np.ndarray) -> None:
    """Turn bodies a by the rotation vectors da [J, 3], b by db (summed per body)."""
    turn = np.zeros((len(q), 3))
    np.add.at(turn, s.a, da)
    np.add.at(turn, s.b, np.where(s.world[:, None], 0.0, db))
    moved = np.flatnonzero(np.abs(turn).max(axis=1) > 0)
    if moved.size:
        q[moved] = quat_normalize(quat_mul(quat_exp(turn[moved]), q[moved]))


def _anchors(j: JointSet, live: np.ndarray, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """World anchor points pa, pb and levers ra, rb (from each centre of mass; rb is 0 for
    the world) of the live joints."""
    a, b = j.a[live], j.b[live]
    ra = _frame_vectors(q, a, j.anchor_a[live])
    rb = _frame_vectors(q, b, j.anchor_b[live])
    world = b < 0
    pa = x[a] + ra
    pb = np.where(world[:, None], rb, x[np.where(world, 0, b)] + rb)
    return pa, pb, ra, np.where(world[:, None], 0.0, rb)


def _angle(j: JointSet, live: np.ndarray, q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The hinge angle (rad) of body a relative to b about the (world) axis: from b's
    reference direction to a's."""
    fa = _frame_vectors(q, j.a[live], j.ref_a[live])
    fb = _frame_vectors(q, j.b[live], j.ref_b[live])
    return np.arctan2(np.einsum("ji,ji->j", axis, cross(fb, fa)), np.einsum("ji,ji->j", fb, fa))


def _project_positions(j: JointSet, live: np.ndarray, s: _Bodies, x: np.ndarray, q: np.ndarray) -> float:
    """One Jacobi pass of the position projection (module docstring, 1); returns the
    largest error it found (m, or rad for a hinge's angles)."""
    kind = j.kind[live]
    pa, pb, ra, rb = _anchors(j, live, x, q)
    d = pa - pb
    dist = np.sqrt(np.einsum("ji,ji->j", d, d))
    n = d / np.where(dist > 0, dist, 1.0)[:, None]
    hinge = kind == HINGE
    C = np.where(kind == PIN, dist, dist - j.length[live])
    C = np.where(((kind == ROPE) & (C < 0)) | hinge, 0.0, C)
    w = _gen_inverse_mass(s, ra, rb, n)
    lam = np.where((w > 0) & (C != 0), -C / np.where(w > 0, w, 1.0), 0.0)
    _apply_linear(s, x, q, ra, rb, lam[:, None] * n)
    worst = float(np.abs(np.where(w > 0, C, 0.0)).max(initial=0.0))
    if not hinge.any():
        return worst
    # a hinge's pivot and axes together: one Newton step of the 5 x 5 system (3 + 2 rows)
    h_ = np.flatnonzero(hinge)
    ua = _frame_vectors(q, j.a[live[h_]], j.axis_a[live[h_]])
    ub = _frame_vectors(q, j.b[live[h_]], j.axis_b[live[h_]])
    e = cross(ua, ub)
    sin = np.sqrt(np.einsum("ji,ji->j", e, e))
    phi = np.arctan2(sin, np.einsum("ji,ji->j", ua, ub))
    turn = e * (phi / np.where(sin > 0, sin, 1.0))[:, None]  # the rotation taking a's axis onto b's
    K, T, ok = _hinge_system(s, h_, ra[h_], rb[h_], ub)
    rhs = np.concatenate((-d[h_], np.einsum("jki,ji->jk", T, turn)), axis=1)
    worst = max(worst, float(np.abs(np.where(ok[:, None], rhs, 0.0)).max(initial=0.0)))
    p_lin, L = _hinge_solve(K, T, rhs, ok)
    full_p = np.zeros((len(kind), 3))
    full_p[h_] = p_lin
    full_L = np.zeros((len(kind), 3))
    full_L[h_] = L
    _apply_linear(s, x, q, ra, rb, full_p)
    _turn(s, q, np.einsum("jik,jk->ji", s.Ia, full_L) * s.share_a[:, None], -np.einsum("jik,jk->ji", s.Ib, full_L) * s.share_b[:, None])
    limited = hinge & np.isfinite(j.limits[live]).any(axis=1)
    if limited.any():
        axis = _frame_vectors(q, j.b[live], j.axis_b[live])
        theta = _angle(j, live, q, axis)
        lo, hi = j.limits[live, 0], j.limits[live, 1]
        err = np.where(theta < lo, lo - theta, np.where(theta > hi, hi - theta, 0.0))
        w = np.einsum("ji,jik,jk->j", axis, s.Ia + s.Ib, axis)
        lam = np.where(limited & (w > 0), err / np.where(w > 0, w, 1.0), 0.0)
        _turn(s, q, np.einsum("jik,jk->ji", s.Ia, axis) * (lam * s.share_a)[:, None], -np.einsum("jik,jk->ji", s.Ib, axis) * (lam * s.share_b)[:, None])
        worst = max(worst, float(np.abs(np.where(lam != 0, err, 0.0)).max(initial=0.0)))
    return worst


def _hinge_system(s: _Bodies, rows: np.ndarray, ra: np.ndarray, rb: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hinges' coupled 5 x 5 matrix (joints `rows` of the live ones): a linear impulse p
    at the pivot and an angular impulse L = T^T l across the axis (T [J, 2, 3], a basis
    across it) change the pivots' relative velocity by K_ll p + K_la l and the relative
    angular velocity across the axis by K_al p + K_aa l, with, per body,
    K_ll = 1/m - [r]x I^-1 [r]x, K_la = -[r]x I^-1 T^T, K_al = T I^-1 [r]x, K_aa = T I^-1 T^T.
    Returns K, T and which hinges have anything to move."""
    helper = np.where(np.abs(axis[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = cross(axis, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    T = np.stack((t1, cross(axis, t1)), axis=1)
    Tt = T.transpose(0, 2, 1)
    K = np.zeros((len(rows), 5, 5))
    for r, m, I in ((ra, s.ma[rows], s.Ia[rows]), (rb, s.mb[rows], s.Ib[rows])):
        S = _skew(r)
        K[:, :3, :3] += m[:, None, None] * np.eye(3)[None] - S @ I @ S
        K[:, :3, 3:] += -S @ I @ Tt
        K[:, 3:, :3] += T @ I @ S
        K[:, 3:, 3:] += T @ I @ Tt
    ok = np.einsum("jii->j", K) > 0
    return K, T, ok


def _hinge_solve(K: np.ndarray, T: np.ndarray, rhs: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve K lambda = rhs for the hinges that can move: (linear impulse [J, 3], angular
    impulse [J, 3] across the axis)."""
    lam = np.zeros((len(K), 5))
    if ok.any():
        lam[ok] = np.linalg.solve(K[ok], rhs[ok][..., None])[..., 0]
    return lam[:, :3], np.einsum("jk,jki->ji", lam[:, 3:], T)


def _skew(r: np.ndarray) -> np.ndarray:
    """[r]x [J, 3, 3]: the matrix of r x ."""
    z = np.zeros(len(r))
    return np.stack((np.stack((z, -r[:, 2], r[:, 1]), 1), np.stack((r[:, 2], z, -r[:, 0]), 1), np.stack((-r[:, 1], r[:, 0], z), 1)), 1)


def _project_velocities(j: JointSet, live: np.ndarray, s: _Bodies, x: np.ndarray, q: np.ndarray, v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """One Jacobi pass of the velocity projection (module docstring, 2); returns the
    impulse magnitude each joint applied (N s) and the largest relative velocity it
    removed (m/s, rad/s)."""
    kind = j.kind[live]
    pa, pb, ra, rb = _anchors(j, live, x, q)
    vb = np.where(s.world[:, None], 0.0, v[s.b] + cross(w[s.b], rb))
    dv = v[s.a] + cross(w[s.a], ra) - vb
    eye = np.eye(3)[None]
    Sa, Sb = _skew(ra), _skew(rb)
    K = (s.ma + s.mb)[:, None, None] * eye - Sa @ s.Ia @ Sa - Sb @ s.Ib @ Sb
    point = kind == PIN
    d = pa - pb
    dist = np.sqrt(np.einsum("ji,ji->j", d, d))
    n = d / np.where(dist > 0, dist, 1.0)[:, None]
    lam = np.zeros((len(kind), 3))
    if point.any():
        ok = point & (np.einsum("jii->j", K) > 0)
        lam[ok] = -np.linalg.solve(K[ok] + 1e-300 * eye, dv[ok][..., None])[..., 0]
    rod = (kind == DISTANCE) | (kind == ROPE)
    if rod.any():
        kn = np.einsum("ji,jik,jk->j", n, K, n)
        vn = np.einsum("ji,ji->j", dv, n)
        taut = (kind == DISTANCE) | ((kind == ROPE) & (dist >= j.length[live] * (1 - 1e-9)) & (vn > 0))
        lam_n = np.where(rod & taut & (kn > 0), -vn / np.where(kn > 0, kn, 1.0), 0.0)
        lam[rod] = (lam_n[:, None] * n)[rod]
    _kick(s, v, w, ra, rb, lam)
    total = np.sqrt(np.einsum("ji,ji->j", lam, lam))
    worst = float(np.abs(np.where(np.einsum("jii->j", K)[:, None] > 0, dv, 0.0)).max(initial=0.0)) if point.any() else 0.0
    if rod.any():
        worst = max(worst, float(np.abs(lam_n * kn).max(initial=0.0)))
    hinge = kind == HINGE
    if hinge.any():
        ang, removed = _hinge_velocities(j, live, s, q, w, hinge, v, ra, rb, dv)
        total += ang
        worst = max(worst, removed)
    return total, worst


def _kick(s: _Bodies, v: np.ndarray, w: np.ndarray, ra: np.ndarray, rb: np.ndarray, lam: np.ndarray) -> None:
    """Apply the impulses lam [J, 3] at the anchors: +lam on a, -lam on b."""
    np.add.at(v, s.a, (s.share_a * s.ma)[:, None] * lam)
    np.add.at(v, s.b, -(s.share_b * s.mb)[:, None] * lam)
    np.add.at(w, s.a, np.einsum("jik,jk->ji", s.Ia, cross(ra, lam)) * s.share_a[:, None])
    np.add.at(w, s.b, np.where(s.world[:, None], 0.0, -np.einsum("jik,jk->ji", s.Ib, cross(rb, lam)) * s.share_b[:, None]))


def _hinge_velocities(j: JointSet, live: np.ndarray, s: _Bodies, q: np.ndarray, w: np.ndarray, hinge: np.ndarray,
                      v: np.ndarray, ra: np.ndarray, rb: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, float]:
    """Remove the hinges' pivot velocity and relative angular velocity across their axes
    together (the 5 x 5 system of _hinge_system) and, at a limit, the part along the axis
    that would pass it. Returns the impulses (N s, N m s) and the largest velocity removed."""
    h_ = np.flatnonzero(hinge)
    axis = _frame_vectors(q, j.b[live[h_]], j.axis_b[live[h_]])
    wb = np.where(s.world[h_, None], 0.0, w[s.b[h_]])
    dw = w[s.a[h_]] - wb
    K, T, ok = _hinge_system(s, h_, ra[h_], rb[h_], axis)
    rhs = -np.concatenate((dv[h_], np.einsum("jki,ji->jk", T, dw)), axis=1)
    removed = float(np.abs(np.where(ok[:, None], rhs, 0.0)).max(initial=0.0))
    p_lin, L = _hinge_solve(K, T, rhs, ok)
    full_p = np.zeros((len(hinge), 3))
    full_p[h_] = p_lin
    full_L = np.zeros((len(hinge), 3))
    full_L[h_] = L
    limited = np.isfinite(j.limits[live[h_]]).any(axis=1)
    if limited.any():
        theta = _angle(j, live[h_], q, axis)
        along = np.einsum("ji,ji->j", dw, axis)
        tol = 1e-9
        lim = j.limits[live[h_]]
        stop = limited & (((theta <= lim[:, 0] + tol) & (along < 0)) | ((theta >= lim[:, 1] - tol) & (along > 0)))
        Kax = s.Ia[h_] + s.Ib[h_]
        ka = np.einsum("ji,jik,jk->j", axis, Kax, axis)
        lam_a = np.where(stop & (ka > 0), -along / np.where(ka > 0, ka, 1.0), 0.0)
        full_L[h_] += lam_a[:, None] * axis
        removed = max(removed, float(np.abs(np.where(stop, along, 0.0)).max(initial=0.0)))
    _kick(s, v, w, ra, rb, full_p)
    np.add.at(w, s.a, np.einsum("jik,jk->ji", s.Ia, full_L) * s.share_a[:, None])
    np.add.at(w, s.b, np.where(s.world[:, None], 0.0, -np.einsum("jik,jk->ji", s.Ib, full_L) * s.share_b[:, None]))
    return np.sqrt(np.einsum("ji,ji->j", full_p, full_p) + np.einsum("ji,ji->j", full_L, full_L)), removed


def constrain(joints: JointSet, x: np.ndarray, q: np.ndarray, v: np.ndarray, w: np.ndarray, inv_mass: np.ndarray, inv_inertia: np.ndarray, h: float) -> None:
    """Stage constrain: project the end-of-step state (in place) onto the joints, positions
    then velocities, `JOINT_ITERATIONS` Jacobi passes each; a joint whose force over the
    step, |impulse| / h, passes its breaking force breaks."""
    live = np.flatnonzero(joints.alive)
    if live.size == 0:
        return
    s = _Bodies(joints, x, q, inv_mass, inv_inertia, live)
    scale = 1.0 + float(np.abs(x).max(initial=0.0))
    for _ in range(JOINT_ITERATIONS):
        if _project_positions(joints, live, s, x, q) <= POSITION_TOL * scale:
            break
    if inv_inertia.any():  # the inertia turned with the bodies
        s = _Bodies(joints, x, q, inv_mass, inv_inertia, live)
    impulse = np.zeros(live.size)
    for _ in range(JOINT_ITERATIONS):
        step_impulse, removed = _project_velocities(joints, live, s, x, q, v, w)
        impulse += step_impulse
        if removed <= VELOCITY_TOL:
            break
    broke = impulse / h > joints.break_force[live]
    joints.alive[live[broke]] = False
