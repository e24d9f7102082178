"""Penalty-force contacts (`contact: penalty`): a spring-damper force from each contact's
depth, part of D(t, X), so every integrator integrates it (RK4 at each of its stages).

Contact model (CG:PP 35.6.5.3; Kelvin-Voigt). Each body is a set of contact points, each a
small sphere fixed in the body (point p, radius rho): a sphere is its centre with its radius,
a capsule the two centres of its caps with its radius, a box its 8 corners, a cylinder 16
samples of its rims, a mesh the vertices of its convex hull (at most MESH_POINTS); against
other bodies a box (or mesh) adds 4 points inside each face and a cylinder an inner ring on
each cap (`_inner_face_points`). A point's
depth in a surface is delta = rho - sdf(point) (> 0: touching), n the surface's outward
normal there. The normal force on the body, at the point of its sphere deepest in the
surface, is

    f_n = k delta + c d(delta)/dt,   d(delta)/dt = -u . n,

with u the velocity of that point relative to the other body. For a point mass this is the
linear oscillator m x'' + c x' + k x = 0 over the contact, whose closed forms give the
restitution e = exp(-zeta pi / sqrt(1 - zeta^2)) and the contact time pi / omega_d, with
omega0 = sqrt(k/m), zeta = c / (2 sqrt(k m)), omega_d = omega0 sqrt(1 - zeta^2): those
relations hold because f_n is kept linear over the whole contact (it may pull slightly just
before separation, as the model's restitution needs). A body at rest on a plane sinks by
m |g| / k (one point) or m |g| / (N k) on N points.

Friction (Coulomb) acts against the tangential slip u_t of the point with max(f_n, 0): it
sticks (the force that stops the slip within the step's dt) while that is at most
mu_s f_n, else slides with mu_k f_n, never more than stops the slip within a step (so it
never reverses it; as forces.coulomb_friction for impulses, with the force times dt as the
impulse). A body with several contacts shares the stopping: each contact stops 1/N.

Surfaces. Static colliders: planes (rectangles, disks; two-sided, the side of the body's
centre), spheres and boxes (exact signed distances). Against a mesh collider a penalty
body keeps its impulses (step.collide). Between two penalty bodies the other body is a
solid with an exact signed distance: round (a sphere or capsule: a segment with a radius),
box (a box, or a mesh's box of bounds) or cylinder. Two round bodies meet at the closest
points of their segments (exact for spheres and capsules); otherwise the points of a round
body enter the other's solid, and the points of two angular bodies (boxes, cylinders,
meshes) each enter the other. Two bodies' springs act in series: k = k_a k_b / (k_a + k_b),
c likewise, so two equal bodies keep their contact time and restitution.

Everything is vectorised over contact points and pairs; nothing loops over bodies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.pose import quat_normalize, quat_to_matrix
from .collisions import BoxCollider, Collider, PlaneCollider, SphereCollider
from .forces import coulomb_friction, cross

ROUND, BOX, CYLINDER = 0, 1, 2  # a body's solid for the others' points
RIM_POINTS = 8  # samples per rim circle of a cylinder
MESH_POINTS = 64  # convex-hull vertices of a mesh body at most (farthest-point subset)
TANGENT_STIFFNESS = 2.0 / 7.0  # k_t / k of static friction's spring (as DEM's linear contacts)
TANGENT_DAMPING = (2.0 / 7.0) ** 0.5  # c_t / c: the tangential spring keeps the normal one's damping ratio
_Y = np.array([0.0, 1.0, 0.0])


def handles(col: Collider) -> bool:
    """Colliders whose contacts with penalty bodies are penalty forces (the others keep
    impulses)."""
    return isinstance(col, (PlaneCollider, SphereCollider, BoxCollider))


@dataclass(frozen=True)
class BodyShape:
    """One body's contact geometry in its own frame: its solid (ROUND: segment of half length
    `half[1]` along Y grown by `radius`; BOX: half extents `half` about `offset`; CYLINDER:
    radius half[0], half height half[1]) and its contact points [k, 3] with radii [k]."""

    solid: int
    half: np.ndarray
    radius: float
    offset: np.ndarray
    points: np.ndarray
    point_radius: np.ndarray
    bodies_only: np.ndarray | None = None  # [k] bool: points used against other bodies only


def _inner_face_points(half: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """4 points on each face of a box, halfway from its centre to its edges ([24, 3]): two
    aligned boxes stacked face to face touch at corners that lie exactly on each other's
    edges (no depth, or the side face's normal); these carry the contact there."""
    out = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for side in (-1.0, 1.0):
            for su in (-0.5, 0.5):
                for sv in (-0.5, 0.5):
                    p = np.zeros(3)
                    p[axis], p[u], p[v] = side * half[axis], su * half[u], sv * half[v]
                    out.append(p)
    return np.array(out) + offset


def sphere_shape(radius: float) -> BodyShape:
    """A sphere: one point, its centre, with its radius."""
    return BodyShape(ROUND, np.zeros(3), radius, np.zeros(3), np.zeros((1, 3)), np.array([radius]))


def capsule_shape(radius: float, length: float) -> BodyShape:
    """A capsule along Y (cylinder part `length`): its caps' centres with its radius."""
    a = 0.5 * length
    return BodyShape(ROUND, np.array([0.0, a, 0.0]), radius, np.zeros(3), np.array([[0.0, -a, 0.0], [0.0, a, 0.0]]), np.full(2, radius))


def box_shape(half: np.ndarray, offset: np.ndarray | None = None, points: np.ndarray | None = None) -> BodyShape:
    """A box of half extents `half` about `offset`: its 8 corners (or the given points, a
    mesh's hull), radius 0."""
    offset = np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64)
    half = np.asarray(half, dtype=np.float64)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64) * half + offset
    pts = np.concatenate((corners if points is None else points, _inner_face_points(half, offset)))
    only = np.arange(len(pts)) >= len(pts) - 24
    return BodyShape(BOX, half, 0.0, offset, pts, np.zeros(len(pts)), only)


def cylinder_shape(radius: float, height: float) -> BodyShape:
    """A cylinder along Y: RIM_POINTS samples on each rim, radius 0."""
    ang = 2 * np.pi * np.arange(RIM_POINTS) / RIM_POINTS
    rims = np.concatenate([np.stack((ring * np.cos(ang), np.full(RIM_POINTS, cap * height / 2), ring * np.sin(ang)), axis=1)
                           for ring in (radius, radius / 2) for cap in (-1.0, 1.0)])
    only = np.arange(len(rims)) >= 2 * RIM_POINTS  # the inner rings: against bodies (see _inner_face_points)
    return BodyShape(CYLINDER, np.array([radius, height / 2, radius]), 0.0, np.zeros(3), rims, np.zeros(len(rims)), only)


def mesh_shape(vertices: np.ndarray) -> BodyShape:
    """A mesh body: the vertices of its convex hull (at most MESH_POINTS, a farthest-point
    subset), and its box of bounds as its solid."""
    from scipy.spatial import ConvexHull, QhullError

    verts = np.asarray(vertices, dtype=np.float64)
    try:
        hull = verts[ConvexHull(verts).vertices]
    except (QhullError, ValueError):  # flat or degenerate: every vertex
        hull = np.unique(verts, axis=0)
    if len(hull) > MESH_POINTS:
        chosen = [int(np.argmax(np.linalg.norm(hull, axis=1)))]
        dist = np.linalg.norm(hull - hull[chosen[0]], axis=1)
        for _ in range(MESH_POINTS - 1):
            chosen.append(int(np.argmax(dist)))
            dist = np.minimum(dist, np.linalg.norm(hull - hull[chosen[-1]], axis=1))
        hull = hull[chosen]
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    return box_shape(0.5 * (hi - lo), 0.5 * (hi + lo), hull)


# --- signed distances in a solid's own frame ([N, 3] points -> distance [N], normal [N, 3]) ---


def _unit(v: np.ndarray, fallback: np.ndarray = _Y) -> tuple[np.ndarray, np.ndarray]:
    norm = np.sqrt(np.einsum("ij,ij->i", v, v))
    return norm, np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None], fallback)


def box_sdf(p: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance to boxes of half extents half [N, 3] at the origin, and the outward
    normal (outside: towards the point from the nearest surface point; inside: the face of
    least depth)."""
    q = np.abs(p) - half
    sign = np.where(p >= 0, 1.0, -1.0)
    out = np.maximum(q, 0.0)
    out_len, out_dir = _unit(out)
    axis = np.argmax(q, axis=1)
    rows = np.arange(len(p))
    inner = np.zeros_like(p)
    inner[rows, axis] = 1.0
    outside = out_len > 0
    d = np.where(outside, out_len, q[rows, axis])
    return d, sign * np.where(outside[:, None], out_dir, inner)


def round_sdf(p: np.ndarray, half_len: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance to capsules along Y (segment of half length half_len [N], grown by
    radius [N]; a sphere when half_len is 0) and the outward normal."""
    foot = np.zeros_like(p)
    foot[:, 1] = np.clip(p[:, 1], -half_len, half_len)
    dist, n = _unit(p - foot)
    return dist - radius, n


def cylinder_sdf(p: np.ndarray, radius: np.ndarray, half_h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance to cylinders along Y (radius, half height [N]) and the outward normal:
    the box distance in the (radial, axial) half-plane."""
    rho = np.hypot(p[:, 0], p[:, 2])
    d, n2 = box_sdf(np.stack((rho, p[:, 1], np.zeros(len(p))), axis=1), np.stack((radius, half_h, np.ones(len(p))), axis=1))
    radial = np.stack((p[:, 0], np.zeros(len(p)), p[:, 2]), axis=1)
    _, e_r = _unit(radial, np.array([1.0, 0.0, 0.0]))
    return d, n2[:, 0:1] * e_r + n2[:, 1:2] * _Y


def segment_closest(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points (c1 on p1 q1, c2 on p2 q2) between segments, [N, 3] each (Ericson,
    Real-Time Collision Detection 5.1.9, vectorised; a segment may be a point)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    tiny = 1e-300
    a_ok, e_ok = a > tiny, e > tiny
    a_s, e_s = np.where(a_ok, a, 1.0), np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    s = np.where(denom > 1e-12 * np.maximum(a * e, tiny), np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e_s
    s = np.where(t < 0, np.clip(-c / a_s, 0.0, 1.0), np.where(t > 1, np.clip((b - c) / a_s, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # a point against a segment, a segment against a point, two points
    s = np.where(~a_ok, 0.0, np.where(~e_ok, np.clip(-c / a_s, 0.0, 1.0), s))
    t = np.where(~e_ok, 0.0, np.where(~a_ok, np.clip(f / e_s, 0.0, 1.0), t))
    return p1 + s[:, None] * d1, p2 + t[:, None] * d2


@dataclass
class Contacts:
    """Touching contact points of one evaluation: body i (pushed along n), body j (-1: a
    static collider), the contact point (world), unit normal, depth (m), the spring's k, c
    and the friction coefficients."""

    i: np.ndarray
    j: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    k: np.ndarray
    c: np.ndarray
    mu: np.ndarray
    mu_s: np.ndarray
    surface: np.ndarray  # [N, 3] m/s: a moving collider's velocity at the point (else 0)
    key: np.ndarray  # [N] int64: the contact's identity from step to step (point, what it touches)


class PenaltySet:
    """The penalty bodies of a rigid group and the surfaces they press on: `forces` is their
    share of D(t, X) (see the module docstring)."""

    def __init__(self, body: np.ndarray, k: np.ndarray, c: np.ndarray, shapes: list[BodyShape | None], colliders: list[Collider],
                 pairs: tuple[np.ndarray, np.ndarray], mass: np.ndarray, inv_mass: np.ndarray, inv_inertia: np.ndarray, radius: np.ndarray,
                 friction: np.ndarray, static_friction: np.ndarray) -> None:
        self.body = body
        self.k, self.c = k, c
        n = len(body)
        self.solid = np.full(n, ROUND)
        self.half = np.zeros((n, 3))
        self.round_radius = np.zeros(n)
        self.offset = np.zeros((n, 3))
        owner, local, rad, only = [], [], [], []
        for b, shape in enumerate(shapes):
            if shape is None or not body[b]:
                continue
            self.solid[b], self.half[b], self.round_radius[b], self.offset[b] = shape.solid, shape.half, shape.radius, shape.offset
            owner.append(np.full(len(shape.points), b))
            local.append(shape.points)
            rad.append(shape.point_radius)
            only.append(shape.bodies_only if shape.bodies_only is not None else np.zeros(len(shape.points), bool))
        self.against_colliders = ~np.concatenate(only) if only else np.zeros(0, bool)
        self.owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
        self.local = np.concatenate(local) if local else np.zeros((0, 3))
        self.point_radius = np.concatenate(rad) if rad else np.zeros(0)
        self.start = np.searchsorted(self.owner, np.arange(n))
        self.count = np.bincount(self.owner, minlength=n)
        self.centred = not self.local.any()  # every point at its body's centre (spheres): no rotation needed
        self.colliders = [col for col in colliders if handles(col)]
        i, j = pairs
        keep = body[i] & body[j]
        self.pairs = (i[keep], j[keep])
        self.mass, self.inv_mass, self.inv_inertia, self.radius = mass, inv_mass, inv_inertia, radius
        self.friction, self.static_friction = friction, static_friction
        self.slots = len(self.colliders) + n  # contact key = point * slots + (collider, or colliders + other body)
        # static friction's springs: the tangential displacement xi [A, 3] (world) of each
        # touching contact since it stuck, by contact key (sorted); advanced after every step
        self.xi_keys = np.zeros(0, np.int64)
        self.xi = np.zeros((0, 3))

    # --- contacts ---------------------------------------------------------------------------

    def contacts(self, x: np.ndarray, rot: np.ndarray | None, moving: np.ndarray, t: float | None = None) -> Contacts | None:
        """Every touching contact point of the state (positions x [n, 3], rotations [n, 3, 3]
        or None when every point is a body's centre) at time t (moving colliders' pose;
        None: where they were last placed)."""
        parts: list[tuple[np.ndarray, ...]] = []
        live = np.flatnonzero(moving[self.owner] & self.against_colliders)
        owner = self.owner[live]
        rad = self.point_radius[live]
        pw = x[owner] if rot is None else x[owner] + np.einsum("pij,pj->pi", rot[owner], self.local[live])
        for ci, col in enumerate(self.colliders):
            m = col.motion
            when = (m.now if t is None else t) if m is not None else 0.0
            if m is None:
                d, n = _collider_sdf(col, pw, x[owner])
            else:  # in its reference frame at time t, the normal back in world space
                d, n = _collider_sdf(col, m.to_reference(when, pw), m.to_reference(when, x[owner]))
                n = m.direction_to_world(when, n)
            depth = rad - d
            touch = depth > 0
            if not touch.any():
                continue
            o = owner[touch]
            point = pw[touch] - rad[touch, None] * n[touch]
            surface = np.zeros((o.size, 3)) if m is None else m.velocity(when, point)
            parts.append((o, np.full(o.size, -1), point, n[touch], depth[touch], self.k[o], self.c[o],
                          np.sqrt(self.friction[o] * col.friction), np.sqrt(self.static_friction[o] * col.static_friction), surface,
                          live[touch].astype(np.int64) * self.slots + ci))
        i, j = self.pairs
        if i.size:
            gap = x[i] - x[j]
            reach = self.radius[i] + self.radius[j]
            near = (np.einsum("ij,ij->i", gap, gap) <= reach * reach) & (moving[i] | moving[j])
            if near.any():
                parts.extend(self._pair_contacts(i[near], j[near], x, rot))
        if not parts:
            return None
        return Contacts(*(np.concatenate(p) for p in zip(*parts)))

    def _pair_contacts(self, i: np.ndarray, j: np.ndarray, x: np.ndarray, rot: np.ndarray | None) -> list[tuple[np.ndarray, ...]]:
        out = []
        round_i, round_j = self.solid[i] == ROUND, self.solid[j] == ROUND
        both = round_i & round_j
        if both.any():  # closest points of the two segments
            a, b = i[both], j[both]
            ax_a = self.half[a, 1, None] * (_Y if rot is None else rot[a, :, 1])
            ax_b = self.half[b, 1, None] * (_Y if rot is None else rot[b, :, 1])
            c1, c2 = segment_closest(x[a] - ax_a, x[a] + ax_a, x[b] - ax_b, x[b] + ax_b)
            dist, n = _unit(c1 - c2)
            depth = self.round_radius[a] + self.round_radius[b] - dist
            touch = depth > 0
            if touch.any():
                a, b, n, depth = a[touch], b[touch], n[touch], depth[touch]
                out.append(self._pair_rows(a, b, c1[touch] - self.round_radius[a, None] * n, n, depth, self.start[a]))
        into_j = ~both & (round_i | ~round_j)  # points of i into the solid of j
        into_i = ~both & (round_j | ~round_i)
        owner = np.concatenate((i[into_j], j[into_i]))
        other = np.concatenate((j[into_j], i[into_i]))
        if owner.size == 0:
            return out
        # every point of each owner against its other: repeat the pair per point
        cnt = self.count[owner]
        pair = np.repeat(np.arange(owner.size), cnt)
        first = np.repeat(np.cumsum(cnt) - cnt, cnt)
        pt = self.start[owner][pair] + (np.arange(pair.size) - first)
        o, t = owner[pair], other[pair]
        rad = self.point_radius[pt]
        pw = x[o] if rot is None else x[o] + np.einsum("pij,pj->pi", rot[o], self.local[pt])
        rel = pw - x[t]
        local = (rel if rot is None else np.einsum("pji,pj->pi", rot[t], rel)) - self.offset[t]
        d = np.empty(len(pt))
        n_local = np.empty((len(pt), 3))
        for kind in (ROUND, BOX, CYLINDER):
            sel = self.solid[t] == kind
            if not sel.any():
                continue
            ts = t[sel]
            if kind == ROUND:
                d[sel], n_local[sel] = round_sdf(local[sel], self.half[ts, 1], self.round_radius[ts])
            elif kind == BOX:
                d[sel], n_local[sel] = box_sdf(local[sel], self.half[ts])
            else:
                d[sel], n_local[sel] = cylinder_sdf(local[sel], self.half[ts, 0], self.half[ts, 1])
        depth = rad - d
        touch = depth > 0
        if touch.any():
            n = n_local[touch] if rot is None else np.einsum("pij,pj->pi", rot[t[touch]], n_local[touch])
            out.append(self._pair_rows(o[touch], t[touch], pw[touch] - rad[touch, None] * n, n, depth[touch], pt[touch]))
        return out

    def _pair_rows(self, a: np.ndarray, b: np.ndarray, point: np.ndarray, n: np.ndarray, depth: np.ndarray, pt: np.ndarray) -> tuple[np.ndarray, ...]:
        # springs in series: 1/k = 1/k_a + 1/k_b (likewise c)
        k = _series(self.k[a], self.k[b])
        c = _series(self.c[a], self.c[b])
        return (a, b, point, n, depth, k, c, np.sqrt(self.friction[a] * self.friction[b]), np.sqrt(self.static_friction[a] * self.static_friction[b]),
                np.zeros((len(a), 3)), pt.astype(np.int64) * self.slots + len(self.colliders) + b)

    # --- forces -----------------------------------------------------------------------------

    def forces(self, x: np.ndarray, q: np.ndarray | None, v: np.ndarray, w: np.ndarray | None, dt: float,
               moving: np.ndarray, t: float | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """Contact forces [n, 3] (N) and torques [n, 3] (N m, world frame) on every body at
        time t (moving colliders' pose), or None when nothing touches. `dt` (s) caps
        friction so that it stops, never reverses, a slip within the step."""
        if not self.owner.size:
            return None
        rot = None if (self.centred or q is None) else quat_to_matrix(quat_normalize(q))
        c = self.contacts(x, rot, moving, t)
        if c is None:
            return None
        static, jj, r_i, r_j, un, u_t = self._slip(c, x, v, w)
        f_n = c.k * c.depth - self._damper(c, x, q, dt, c.normal, c.c, static, jj, r_i, r_j) * un  # k delta + c d(delta)/dt, d(delta)/dt = -u.n
        f_t = self._friction(c, x, q, dt, f_n, u_t, static, jj, r_i, r_j)
        f = f_n[:, None] * c.normal + f_t
        force = np.zeros_like(x)
        torque = np.zeros_like(x)
        np.add.at(force, c.i, f)
        np.add.at(torque, c.i, cross(r_i, f))
        if not static.all():
            pj = ~static
            np.add.at(force, c.j[pj], -f[pj])
            np.add.at(torque, c.j[pj], cross(r_j[pj], -f[pj]))
        return force, torque

    def _slip(self, c: Contacts, x: np.ndarray, v: np.ndarray, w: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Per contact: static (bool), the other body (0 for a static one), the levers r_i, r_j,
        and the relative velocity of the point u (body i against the other surface): its
        normal part u.n and its tangential part u_t [N, 3]."""
        static = c.j < 0
        jj = np.where(static, 0, c.j)
        r_i = c.point - x[c.i]
        r_j = c.point - x[jj]
        u = v[c.i] - np.where(static[:, None], 0.0, v[jj]) - c.surface
        if w is not None:
            u = u + cross(w[c.i], r_i) - np.where(static[:, None], 0.0, cross(w[jj], r_j))
        un = np.einsum("ij,ij->i", u, c.normal)
        return static, jj, r_i, r_j, un, u - un[:, None] * c.normal

    def _springs(self, c: Contacts) -> np.ndarray:
        """Each contact's static-friction displacement xi [N, 3] (0 for a new contact), turned
        into the contact's tangent plane (its length kept)."""
        xi = np.zeros((c.key.size, 3))
        if self.xi_keys.size:
            at = np.clip(np.searchsorted(self.xi_keys, c.key), 0, self.xi_keys.size - 1)
            same = self.xi_keys[at] == c.key
            xi[same] = self.xi[at[same]]
        length = np.sqrt(np.einsum("ij,ij->i", xi, xi))
        flat = xi - np.einsum("ij,ij->i", xi, c.normal)[:, None] * c.normal
        flat_len = np.sqrt(np.einsum("ij,ij->i", flat, flat))
        return flat * np.where(flat_len > 0, length / np.where(flat_len > 0, flat_len, 1.0), 0.0)[:, None]

    def _damper(self, c: Contacts, x: np.ndarray, q: np.ndarray | None, dt: float, d: np.ndarray, coef: np.ndarray, static: np.ndarray,
                jj: np.ndarray, r_i: np.ndarray, r_j: np.ndarray) -> np.ndarray:
        """The damping coefficients `coef` [N] along directions d [N, 3], capped so that no
        damper reverses the relative velocity along d within the step dt: c <= 1 / (dt K s),
        K = the point's inverse effective mass along d (both bodies), s = the most contacts
        of either body (they act together). Without it a stack of bodies, whose dampers add
        up in series, is unstable under an explicit step (h c_total / m > 2)."""
        k = self._tangent_inverse_mass(c.i, r_i, d, q) + np.where(static, 0.0, self._tangent_inverse_mass(jj, r_j, d, q))
        share = np.bincount(c.i, minlength=len(x)) + np.bincount(c.j[~static], minlength=len(x))
        k = k * np.maximum(share[c.i], np.where(static, 0, share[jj]))
        h = dt if dt > 0 else 1.0
        return np.minimum(coef, 1.0 / np.where(k > 0, k * h, 1e-300))

    def _friction(self, c: Contacts, x: np.ndarray, q: np.ndarray | None, dt: float, f_n: np.ndarray, u_t: np.ndarray, static: np.ndarray,
                  jj: np.ndarray, r_i: np.ndarray, r_j: np.ndarray) -> np.ndarray:
        """Friction forces [N, 3] on body i (stick-slip, see the module docstring): the
        tangential spring-damper -k_t xi - c_t u_t while it stays inside the static cone
        mu_s f_n, else mu_k f_n along it. The damper is capped at what stops the slip within
        dt (shared by the body's contacts), so it never reverses a slip within a step."""
        press = np.maximum(f_n, 0.0)
        _, t_hat = _unit(u_t, np.zeros(3))
        damper = self._damper(c, x, q, dt, t_hat, TANGENT_DAMPING * c.c, static, jj, r_i, r_j)
        trial = -(TANGENT_STIFFNESS * c.k)[:, None] * self._springs(c) - damper[:, None] * u_t
        size = np.sqrt(np.einsum("ij,ij->i", trial, trial))
        slides = size > c.mu_s * press
        scale = np.where(slides, c.mu * press / np.where(size > 0, size, 1.0), 1.0)
        return trial * scale[:, None]

    def advance(self, x: np.ndarray, q: np.ndarray | None, v: np.ndarray, w: np.ndarray | None, moving: np.ndarray, dt: float,
                t: float | None = None) -> None:
        """After a step: each touching contact's static-friction spring moves with the slip
        of the step, xi <- xi + u_t dt (turned into the contact's tangent plane), and a spring
        stretched past the static cone (k_t |xi| > mu_s f_n) is reset to the kinetic one
        (k_t |xi| = mu_k f_n: the contact slipped there). Contacts no longer touching are
        forgotten."""
        if not self.owner.size:
            return
        rot = None if (self.centred or q is None) else quat_to_matrix(quat_normalize(q))
        c = self.contacts(x, rot, moving, t)
        if c is None:
            self.xi_keys, self.xi = np.zeros(0, np.int64), np.zeros((0, 3))
            return
        static, jj, r_i, r_j, un, u_t = self._slip(c, x, v, w)
        xi = self._springs(c) + dt * u_t
        k_t = TANGENT_STIFFNESS * c.k
        press = np.maximum(c.k * c.depth - self._damper(c, x, q, dt, c.normal, c.c, static, jj, r_i, r_j) * un, 0.0)
        length = np.sqrt(np.einsum("ij,ij->i", xi, xi))
        over = k_t * length > c.mu_s * press
        reset = np.where(over, c.mu * press / np.where(k_t * length > 0, k_t * length, 1.0), 1.0)
        order = np.argsort(c.key)
        self.xi_keys, self.xi = c.key[order], (xi * reset[:, None])[order]

    def _tangent_inverse_mass(self, b: np.ndarray, r: np.ndarray, t: np.ndarray, q: np.ndarray | None) -> np.ndarray:
        """1/m + (r x t) . I^-1 (r x t): the point's velocity change along t per unit impulse."""
        out = self.inv_mass[b].copy()
        inv_i = self.inv_inertia[b]
        if not inv_i.any():
            return out
        rxt = cross(r, t)
        if q is not None and not (inv_i == inv_i[:, :1]).all():
            rot = quat_to_matrix(quat_normalize(q[b]))
            rxt = np.einsum("pji,pj->pi", rot, rxt)  # into the body frame
        return out + np.einsum("pi,pi->p", rxt * inv_i, rxt)

    def collider_power(self, x: np.ndarray, q: np.ndarray | None, v: np.ndarray, moving: np.ndarray, t: float) -> float:
        """The power (W) the moving colliders' springs put into the bodies at time t,
        sum max(0, k depth n . u) over their contacts (u: the surface's velocity)."""
        if not self.owner.size or not any(col.motion is not None for col in self.colliders):
            return 0.0
        rot = None if (self.centred or q is None) else quat_to_matrix(quat_normalize(q))
        c = self.contacts(x, rot, moving, t)
        if c is None:
            return 0.0
        return float(np.maximum(c.k * c.depth * np.einsum("ij,ij->i", c.normal, c.surface), 0.0).sum())

    def energy(self, x: np.ndarray, q: np.ndarray | None, moving: np.ndarray) -> float:
        """Energy held in the contact springs, sum 1/2 k delta^2 (J)."""
        if not self.owner.size:
            return 0.0
        rot = None if (self.centred or q is None) else quat_to_matrix(quat_normalize(q))
        c = self.contacts(x, rot, moving)
        return 0.0 if c is None else float(0.5 * np.einsum("i,i,i->", c.k, c.depth, c.depth))


def _series(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    total = a + b
    return np.where(total > 0, a * b / np.where(total > 0, total, 1.0), 0.0)


def _collider_sdf(col: Collider, p: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of points p [N, 3] to a static collider and its outward normal (a
    two-sided plane's outside is the side of the body's centre; a point beyond a
    rectangle's or disk's edge is not touching it)."""
    if isinstance(col, PlaneCollider):
        side = np.where((centre - col.point) @ col.normal >= 0, 1.0, -1.0)
        rel = p - col.point
        d = side * (rel @ col.normal)
        pu, pv = rel @ col.u, rel @ col.v
        inside = pu * pu + pv * pv <= col.disk_radius**2 if col.disk_radius is not None else (np.abs(pu) <= col.half_u) & (np.abs(pv) <= col.half_v)
        return np.where(inside, d, np.inf), side[:, None] * col.normal[None, :]
    if isinstance(col, SphereCollider):
        dist, n = _unit(p - col.center)
        return dist - col.radius, n
    if isinstance(col, BoxCollider):
        d, n_local = box_sdf((p - col.center) @ col.rotation, np.broadcast_to(col.half, p.shape))
        return d, n_local @ col.rotation.T
    raise TypeError(f"no penalty contact with {type(col).__name__}")
