"""True-shape contacts of rigid boxes (`shape: cube`) and cylinders against static colliders.

Spheres (and other shapes) keep colliding as their bounding sphere (collisions.py); boxes
and cylinders collide with their true shape against planes/rectangles/disks, boxes and
spheres. Mesh colliders (and body-body pairs) still see their bounding sphere.

One pass (the collide stage calls it inside its `contact_iterations` loop):

1. Broad phase. The centre's segment x0 -> x1 swept with the bounding radius against each
   collider (collisions.Collider.sweep): a body whose bounding sphere stays clear of a
   collider over the whole step cannot touch it with its true shape.
2. Contact points. Candidate points fixed in the body (body frame, [k, 3]):
   box: its 8 corners (edge and face contacts against a plane or a box face are two or
   four corners); sphere collider: also the point of the body closest to the sphere's
   centre. Cylinder (axis +Y, radius r, half height c): 8 samples on each rim circle (a
   cap resting flat stands on them), plus the analytically deepest rim point per cap in
   each of the collider's normal directions d (plane: its normal; box: its 6 face
   normals): p = r (d_xz / |d_xz|) -/+ c Y in the body frame (d_b = R^T d); sphere: the
   cylinder's closest point to the centre. Each point moves over the step from its start
   pose x0 + R0 p to its end pose x1 + R1 p and that segment is swept against the
   collider (radius 0), so a fast body cannot tunnel: the 520 m/s box's corners cross the
   plane within the step and are caught. A plane's side is the side of the body's centre
   at the start (a corner slightly through stays on the right side). Depth at the end
   of the step, along the normal: depth = depth0 + n . (p(s) - p1).
3. Impulses (sequential impulses / projected Gauss-Seidel, per body over its contacts,
   vectorised over bodies). At contact a with lever r_a (from the centre of mass, end
   orientation) and direction d (normal n or a tangent), a unit impulse along d changes
   the point's velocity along d by k = 1/m + d . ((I^-1 (r x d)) x r) (from
   dv = d/m, dw = I^-1 (r x d), du = dv + dw x r). So the normal impulse that gives the
   relative normal velocity u.n -> -eps u.n is
       j = -(1 + eps) u.n / (1/m + n . ((I^-1 (r x n)) x r)),
   eps = min(eps_body, eps_collider) (0 below the resting speed v_rest = 2 |g| h).
   With several contacts the coupling K_ab = d_a/m . d_b + (r_a x d_a) . I^-1 (r_b x d_b)
   is assembled per body ([3m, 3m]: normal and two tangents per contact) and the
   accumulated impulses are iterated: for `4 * contact_iterations` sweeps over the
   contacts in order, lambda_n <- max(0, lambda_n + (target - u_n) / K_nn) (accumulated
   impulse clamped at 0: contacts push, never pull), then the tangential pair
   lambda_t <- lambda_t - u_t / K_tt, clamped to the disk |lambda_t| <= mu_s lambda_n
   (static) or, if that does not hold it, mu_k lambda_n (kinetic); mu = sqrt(mu_a mu_b).
   A sweep that changes no contact velocity by more than 1 nm/s ends the iteration.
   Warm start: contacts persist by key (body, candidate point, collider); a contact that
   was there last step (and is not an impact) starts from last step's impulses, so a
   resting box converges in one sweep. Every update minimises the kinetic energy change
   1/2 l.K l + l.u0 over one contact, so an inelastic contact never adds energy.
   Pinned or held bodies are infinite mass: they are never in the shaped set.
4. Positions. An impact happened at the time of impact s: the rest of the step moves with
   the changed velocities, x1 += (1 - s) h dv, q1 rotated by (1 - s) h dw. A resting
   contact (no approach faster than v_rest) is a support force over the step, so the
   lever is half that (trapezoid) like the spheres' friction. Then what still penetrates
   is removed by translating along the normal of the deepest contact (three passes, for
   contacts with different normals). Lifting back by what gravity pulled in during the
   step removes what the integrator added: a resting box keeps its energy and position.
   When the depth came from a rotation the translation can add up to m |g| depth of
   potential energy (documented bound; about 1e-6 of the energy dropped in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import BOX
from ..motion.pose import quat_mul, quat_normalize, quat_to_matrix
from .forces import cross
from .collisions import TOL, BoxCollider, Collider, ContactBodies, PlaneCollider, SphereCollider

RIM_SAMPLES = 8
_POINT_IDS = 64  # candidate points per body and collider (at most 28 used)


@dataclass
class ShapeSet:
    """Per body: kind (geometry.py BOUND 0: bounding sphere, BOX 1, CYLINDER 2) and half extents [n, 3]
    in the body frame (box: half sizes; cylinder along +Y: (r, h/2, r)), scale applied."""

    kind: np.ndarray
    half: np.ndarray
    # warm start: the accumulated impulses of the last step's contacts, by contact key
    # (body, candidate point, collider), sorted
    prev_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    prev_lam: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    keys: list[np.ndarray] = field(default_factory=list)
    lams: list[np.ndarray] = field(default_factory=list)
    # box-box contacts (island.py): per body pair, the contact points in b's frame and their
    # accumulated impulses, last step's and this step's
    pair_prev: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    pair_next: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    # sleeping (island.py): how long each body has been calm (s), and the pose it sleeps at
    calm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rest_x: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rest_q: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    sleeping: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self) -> None:
        n = len(self.kind)
        self.calm, self.rest_x, self.rest_q, self.sleeping = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 4)), np.zeros(n, bool)

    def shaped(self) -> np.ndarray:
        """Bodies that collide with their true shape (not their bounding sphere)."""
        return self.kind > 0

    def begin_step(self) -> None:
        """The contacts stored during the last step become the warm start of this one."""
        if self.keys:
            k, lam = np.concatenate(self.keys), np.concatenate(self.lams)
            order = np.argsort(k)
            self.prev_keys, self.prev_lam = k[order], lam[order]
        else:
            self.prev_keys, self.prev_lam = np.zeros(0, np.int64), np.zeros((0, 3))
        self.keys, self.lams = [], []
        self.pair_prev, self.pair_next = self.pair_next, {}


def true_shape_collider(col: Collider) -> bool:
    """Colliders against which boxes and cylinders use their true shape (static ones: a
    moving collider meets their bounding sphere)."""
    return col.motion is None and isinstance(col, (PlaneCollider, BoxCollider, SphereCollider))


_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
_ANG = 2 * np.pi * np.arange(RIM_SAMPLES) / RIM_SAMPLES
_RIM = np.concatenate([np.stack((np.cos(_ANG), np.full(RIM_SAMPLES, cap), np.sin(_ANG)), axis=1) for cap in (-1.0, 1.0)])


def _directions(col: Collider, x0: np.ndarray) -> np.ndarray:
    """[n, k, 3] unit directions from the body towards the collider's surface (where the
    deepest points of a cylinder's rims lie)."""
    if isinstance(col, PlaneCollider):
        side = np.where((x0 - col.point) @ col.normal >= 0, 1.0, -1.0)
        return -side[:, None, None] * col.normal[None, None, :]
    if isinstance(col, BoxCollider):
        faces = np.concatenate((col.rotation.T, -col.rotation.T))  # outward face normals
        return np.broadcast_to(-faces[None], (len(x0), 6, 3))
    return np.zeros((len(x0), 0, 3))


def body_points(kind: np.ndarray, half: np.ndarray, rot1: np.ndarray, x1: np.ndarray, x0: np.ndarray, col: Collider) -> tuple[np.ndarray, np.ndarray]:
    """Candidate contact points in the body frame, [n, k, 3], and a validity mask [n, k]
    (boxes and cylinders have different counts; the shorter rows are padded)."""
    n = len(kind)
    box = kind == BOX
    corners = _CORNERS[None] * half[:, None, :]  # [n, 8, 3]
    rim = _RIM[None] * half[:, None, :]  # [n, 16, 3]: r cos, +-c, r sin
    base = np.where(box[:, None, None], np.concatenate((corners, np.zeros((n, 8, 3))), axis=1), rim)
    valid = np.concatenate((np.ones((n, 8), bool), np.broadcast_to(~box[:, None], (n, 8))), axis=1)
    extra, extra_ok = [], []
    d = _directions(col, x0)
    if d.shape[1]:
        d_b = np.einsum("nji,nkj->nki", rot1, d)  # R^T d, [n, k, 3]
        radial = d_b * np.array([1.0, 0.0, 1.0])
        length = np.linalg.norm(radial, axis=2)
        ok = (length > 1e-9) & ~box[:, None]
        unit = radial / np.where(length > 1e-9, length, 1.0)[..., None]
        r = half[:, None, 0:1]
        for cap in (-1.0, 1.0):
            extra.append(unit * r + np.array([0.0, 1.0, 0.0]) * cap * half[:, None, 1:2])
            extra_ok.append(ok)
    if isinstance(col, SphereCollider):
        c_b = np.einsum("nji,nj->ni", rot1, col.center[None, :] - x1)
        p_box = np.clip(c_b, -half, half)
        rho = np.hypot(c_b[:, 0], c_b[:, 2])
        shrink = np.minimum(1.0, half[:, 0] / np.where(rho > 0, rho, 1.0))
        p_cyl = np.stack((c_b[:, 0] * shrink, np.clip(c_b[:, 1], -half[:, 1], half[:, 1]), c_b[:, 2] * shrink), axis=1)
        extra.append(np.where(box[:, None], p_box, p_cyl)[:, None, :])
        extra_ok.append(np.ones((n, 1), bool))
    if extra:
        base = np.concatenate([base] + extra, axis=1)
        valid = np.concatenate([valid] + extra_ok, axis=1)
    return base, valid


def point_hits(col: Collider, p0: np.ndarray, p1: np.ndarray, c0: np.ndarray):
    """Swept points p0 -> p1 ([N, 3]) against a collider, radius 0. Returns hit, s,
    normal (towards the body), depth at the end of the step (m, > 0 penetrating)."""
    zero = np.zeros(len(p0))
    # a point on the surface may start behind a (two-sided) plane: the body centre's side
    # is the outside
    h = col.sweep(p0, p1, zero, side_from=c0) if isinstance(col, PlaneCollider) else col.sweep(p0, p1, zero)
    at = p0 + h.s[:, None] * (p1 - p0)
    # depth at the end of the step: the start depth plus the travel into the surface
    depth = h.depth0 + np.einsum("ij,ij->i", h.normal, at - p1)
    return h.hit & (depth > TOL), h.s, h.normal, depth


@dataclass
class Contacts:
    """Contacts of the shaped bodies, padded per body: [B, m] / [B, m, 3]."""

    body: np.ndarray  # [B] body index
    ok: np.ndarray  # [B, m]
    lever: np.ndarray  # [B, m, 3] r = R1 p (world, from the centre of mass)
    local: np.ndarray  # [B, m, 3] p (body frame)
    normal: np.ndarray
    depth: np.ndarray
    s: np.ndarray
    eps: np.ndarray  # collider restitution
    mu: np.ndarray
    mu_s: np.ndarray
    collider: np.ndarray  # index into the collider list
    key: np.ndarray  # (body * 64 + candidate point) * colliders + collider, -1 padding


def find_contacts(b: ContactBodies, shapes: ShapeSet, idx: np.ndarray, q0: np.ndarray, q1: np.ndarray, colliders: list[Collider]) -> Contacts | None:
    """All true-shape contacts of bodies idx (shaped, moving) against the colliders."""
    rot0 = quat_to_matrix(quat_normalize(q0[idx]))
    rot1 = quat_to_matrix(quat_normalize(q1[idx]))
    x0, x1 = b.x0[idx], b.x1[idx]
    kind, half = shapes.kind[idx], shapes.half[idx]
    parts = []
    for ci, col in enumerate(colliders):
        if not true_shape_collider(col):
            continue
        near = np.flatnonzero(col.sweep(x0, x1, b.radius[idx]).hit)
        if near.size == 0:
            continue
        local, valid = body_points(kind[near], half[near], rot1[near], x1[near], x0[near], col)
        k = local.shape[1]
        p0 = x0[near, None, :] + np.einsum("nij,nkj->nki", rot0[near], local)
        lever = np.einsum("nij,nkj->nki", rot1[near], local)
        p1 = x1[near, None, :] + lever
        c0 = np.repeat(x0[near], k, axis=0)
        hit, s, normal, depth = point_hits(col, p0.reshape(-1, 3), p1.reshape(-1, 3), c0)
        hit = hit.reshape(len(near), k) & valid
        rows, cols = np.nonzero(hit)
        if rows.size == 0:
            continue
        flat = rows * k + cols
        key = (idx[near[rows]].astype(np.int64) * _POINT_IDS + cols) * len(colliders) + ci
        parts.append((near[rows], local[rows, cols], lever[rows, cols], normal[flat], depth[flat], s[flat], np.full(rows.size, ci), key))
    if not parts:
        return None
    body, local, lever, normal, depth, s, cidx, key = (np.concatenate(p) for p in zip(*parts))
    # pad per body: slot = rank of the contact within its body
    order = np.argsort(body, kind="stable")
    body, local, lever, normal, depth, s, cidx, key = body[order], local[order], lever[order], normal[order], depth[order], s[order], cidx[order], key[order]
    uniq, start, count = np.unique(body, return_index=True, return_counts=True)
    row = np.searchsorted(uniq, body)
    slot = np.arange(body.size) - start[row]
    B, m = uniq.size, int(count.max())

    def pad(a: np.ndarray, fill: float = 0.0) -> np.ndarray:
        out = np.full((B, m) + a.shape[1:], fill, dtype=a.dtype)
        out[row, slot] = a
        return out

    eps = np.array([c.restitution for c in colliders])[cidx]
    mu = np.array([c.friction for c in colliders])[cidx]
    mu_s = np.array([c.static_friction for c in colliders])[cidx]
    return Contacts(idx[uniq], pad(np.ones(body.size, bool), False), pad(lever), pad(local), pad(normal), pad(depth), pad(s, 1.0), pad(eps), pad(mu), pad(mu_s), pad(cidx, -1), pad(key, -1))


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents orthogonal to unit normals n [..., 3]."""
    helper = np.where(np.abs(n[..., 0:1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    t1 = cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, cross(n, t1)


def _rotate(q: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """q rotated by the world-frame rotation vector theta (exact exponential map)."""
    angle = np.linalg.norm(theta, axis=1)
    half = 0.5 * angle
    axis = theta / np.where(angle > 0, angle, 1.0)[:, None]
    dq = np.concatenate((np.cos(half)[:, None], np.sin(half)[:, None] * axis), axis=1)
    return quat_normalize(quat_mul(dq, q))


def resolve_shaped(b: ContactBodies, c: Contacts, shapes: ShapeSet, q1: np.ndarray, h: float, v_rest: float, sweeps: int) -> np.ndarray:
    """Impulses, then positions, for the contacts c (in place on b and q1). Returns [7, k]:
    body, approach speed (m/s), collider index, time of impact (fraction of the step),
    centre (x, y, z) of each body that had an impact this pass."""
    i = c.body
    B, m = c.ok.shape
    inv_m = b.inv_mass[i]
    inv_I = b.inv_inertia_world[i] if b.inv_inertia_world is not None else np.zeros((B, 3, 3))
    n = c.normal
    D, A, K, u0 = _contact_space(b, c, inv_m, inv_I)
    u0n = u0[:, 0::3]
    rel = np.einsum("bmk,bmk->bm", n, n)  # 1 for real contacts
    impact = c.ok & (-u0n > v_rest)
    eps = np.where(impact, np.minimum(b.restitution[i][:, None], c.eps), 0.0)
    target = np.where(c.ok & (u0n < 0), -eps * u0n, 0.0) * rel
    mu = np.sqrt(b.friction[i][:, None] * c.mu)
    mu_s = np.sqrt(b.static_friction[i][:, None] * c.mu_s)
    lam = _warm_start(shapes, c, impact)
    lam = _solve_impulses(K, u0, target, mu, mu_s, lam, sweeps)
    shapes.keys.append(c.key[c.ok])
    shapes.lams.append(lam.reshape(B, m, 3)[c.ok])
    dv = inv_m[:, None] * np.einsum("bi,bik->bk", lam, D)
    dw = np.einsum("bkl,bl->bk", inv_I, np.einsum("bi,bik->bk", lam, A))
    b.v1[i] += dv
    if b.w1 is not None:
        b.w1[i] += dw
    # positions: the rest of the step after an impact; half of it for a support
    hit_body = impact.any(axis=1)
    s_first = np.where(c.ok, c.s, 1.0).min(axis=1)
    lever_t = np.where(hit_body, 1.0 - s_first, 0.5) * h
    b.x1[i] += lever_t[:, None] * dv
    q1[i] = _rotate(q1[i], lever_t[:, None] * dw)
    _depenetrate(b, c, q1, lever_t[:, None] * dv)
    speed = np.where(impact, -u0n, 0.0)
    best = np.argmax(speed, axis=1)
    sel = np.flatnonzero(hit_body)
    xs = b.x1[i[sel]]
    return np.concatenate((np.stack((i[sel].astype(np.float64), speed[sel, best[sel]], c.collider[sel, best[sel]].astype(np.float64), s_first[sel])), xs.T))


def _contact_space(b: ContactBodies, c: Contacts, inv_m: np.ndarray, inv_I: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The contacts' directions D [B, 3m, 3] (rows: contact a, direction n, t1, t2; zero
    for padded contacts), their levers' moments A = r x d, the effective mass matrix
    K = D D^T / m + A I^-1 A^T [B, 3m, 3m], and the velocities along D before the impulses."""
    i = c.body
    B, m = c.ok.shape
    n = c.normal
    t1, t2 = _tangents(np.where(c.ok[..., None], n, np.array([0.0, 1.0, 0.0])))
    D = np.stack((n, t1, t2), axis=2).reshape(B, 3 * m, 3)  # rows: contact a, direction (n, t1, t2)
    D = D * np.repeat(c.ok, 3, axis=1)[..., None]
    r = np.repeat(c.lever, 3, axis=1)
    A = cross(r, D)  # r x d
    K = inv_m[:, None, None] * np.einsum("bik,bjk->bij", D, D) + np.einsum("bik,bkl,bjl->bij", A, inv_I, A)
    u0 = np.einsum("bik,bk->bi", D, b.v1[i]) + (np.einsum("bik,bk->bi", A, b.w1[i]) if b.w1 is not None else 0.0)
    return D, A, K, u0


def _warm_start(shapes: ShapeSet, c: Contacts, impact: np.ndarray) -> np.ndarray:
    """The impulses [B, 3m] the iteration starts from: a contact that was there last step
    (same body, point and collider) and is no new impact starts from last step's
    impulses; the iteration then corrects them (clamped). Zero otherwise."""
    B, m = c.ok.shape
    lam = np.zeros((B, 3 * m))
    if shapes.prev_keys.size:
        at = np.clip(np.searchsorted(shapes.prev_keys, c.key), 0, shapes.prev_keys.size - 1)
        same = (shapes.prev_keys[at] == c.key) & c.ok & ~impact
        lam = np.where(same[..., None], shapes.prev_lam[at], 0.0).reshape(B, 3 * m)
    return lam


def _solve_impulses(K: np.ndarray, u0: np.ndarray, target: np.ndarray, mu: np.ndarray, mu_s: np.ndarray, lam: np.ndarray, sweeps: int) -> np.ndarray:
    """Projected Gauss-Seidel over the contacts, at most `sweeps` sweeps: each contact's
    normal impulse clamped to push only (towards the target normal speed), its friction
    impulse to the static cone (mu_s) or else the kinetic one (mu). In place on `lam`."""
    m = target.shape[1]
    diag = np.einsum("bii->bi", K)
    diag = np.where(diag > 1e-300, diag, 1.0)
    # padded contacts have zero rows in K, zero target and u0: their impulses stay 0
    k_rows = [np.ascontiguousarray(K[:, 3 * a : 3 * a + 3, :]) for a in range(m)]
    k_tn = [K[:, 3 * a + 1 : 3 * a + 3, 3 * a] for a in range(m)]
    inv_d = 1.0 / diag
    for _ in range(sweeps):
        before = lam.copy()
        for a in range(m):
            na = 3 * a
            u = u0[:, na : na + 3] + np.einsum("bij,bj->bi", k_rows[a], lam)
            ln = np.maximum(0.0, lam[:, na] + (target[:, a] - u[:, 0]) * inv_d[:, na])
            dn = ln - lam[:, na]
            lam[:, na] = ln
            lt = lam[:, na + 1 : na + 3] - (u[:, 1:] + k_tn[a] * dn[:, None]) * inv_d[:, na + 1 : na + 3]
            norm = np.sqrt(lt[:, 0] ** 2 + lt[:, 1] ** 2)
            cap = np.where(norm <= mu_s[:, a] * ln, norm, mu[:, a] * ln)
            lam[:, na + 1 : na + 3] = lt * (cap / np.where(norm > 0, norm, 1.0))[:, None]
        # converged when a sweep changes no contact velocity by more than 1 nm/s
        if np.abs(np.einsum("bij,bj->bi", K, lam - before)).max() <= 1e-9:
            break
    return lam


def _depenetrate(b: ContactBodies, c: Contacts, q1: np.ndarray, moved: np.ndarray) -> None:
    """Remove what still penetrates after the bodies moved by `moved` [B, 3] and turned to
    q1: translate each along its deepest contact's normal (three passes at most)."""
    i = c.body
    n = c.normal
    rows = np.arange(c.ok.shape[0])
    rot = quat_to_matrix(q1[i])
    lever_new = np.einsum("bij,bmj->bmi", rot, c.local)
    depth = c.depth - np.einsum("bmk,bmk->bm", n, lever_new - c.lever) - np.einsum("bmk,bk->bm", n, moved)
    for _ in range(3):
        depth = np.where(c.ok, depth, -np.inf)
        k = np.argmax(depth, axis=1)
        lift = np.maximum(depth[rows, k], 0.0)
        if not (lift > 0).any():
            break
        move = lift[:, None] * n[rows, k]
        b.x1[i] += move
        depth = depth - np.einsum("bmk,bk->bm", n, move)
