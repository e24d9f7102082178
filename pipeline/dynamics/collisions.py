"""Collisions: swept detection over each step and impulse resolution outside the integrator.

Scheme (one step, after the integrator moved every body from (x0, v0) to (x1, v1)):

1. Sweep. Each body's centre moves along the segment x0 -> x1; a static collider is
   inflated by the body's radius, so the segment against the inflated shape gives the
   time of impact s in [0, 1] (plane: linear; sphere: quadratic; box: slab test; mesh:
   per triangle plane + barycentric test, then the cylinders about its edges and the
   spheres about its vertices). A body that crosses a surface within one step is caught
   wherever it ends: nothing tunnels, whatever the speed.
2. Resolve (static collider): at the contact, v_c = v0 + s (v1 - v0) is the velocity and
   n the unit normal towards the body. Restitution eps = min(eps_body, eps_collider);
   below a resting speed v_rest = 2 |g| h the contact is treated as resting (eps = 0).
   Normal impulse, from (v + j n / m) . n = -eps v . n:  j = -(1 + eps) m v_c . n.
   The rest of the step continues from the contact with the post-impact velocity plus
   the step's own velocity change (1 - s)(v1 - v0). A body ending below the contact
   surface is projected back onto it and its normal velocity clamped to >= 0 (the
   support impulse of resting contact: what gravity added during the step, removed
   again; no energy is added, so a ball at rest stays exactly at rest).
   Friction acts at the contact point r = -radius n on the slip velocity
   u = v + w x r: the impulse along -u_t is Coulomb (forces.coulomb_friction) with the
   total normal impulse, mu = sqrt(mu_body mu_collider), and effective inverse mass
   k_t = 1/m + t . ((I^-1 (r x t)) x r); it never reverses the slip.
   Boxes and cylinders use their true shape against plane, box and sphere colliders
   (shapes.py); this module's bounding-sphere sweep is their broad phase.
3. Sphere-sphere between bodies: the relative segment against radius r_i + r_j; with
   n from j to i and v_rel = v_i - v_j (end-of-step velocities),
   J = -(1 + eps) v_rel . n / (1/m_i + 1/m_j), applied +J n to i and -J n to j, so
   momentum is conserved exactly; the overlap left is removed by moving the two apart
   in the ratio of their inverse masses (which keeps the centre of mass).
   Pinned bodies have 1/m = 0 and 1/I = 0: they take no impulse and never move.
4. Simultaneous contacts: Gauss-Seidel over the colliders in scene order (each collider
   acts on all bodies at once, vectorised), then the body pairs (Jacobi: all pairs'
   impulses summed at once); repeated up to `contact_iterations` times until a pass
   finds no penetration. The earlier contacts of a pass see the later ones' effects
   on the next pass.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .forces import coulomb_friction, cross

TOL = 1e-9  # m: penetrations smaller than this are contact, not collision
_MESH_CHUNK = 2_000_000  # bodies x triangles tested at once
_SCREEN_FROM = 4096  # bodies: from this many on, plane sweeps screen before the exact test


@dataclass
class Hits:
    """Swept contacts of n bodies against one collider over a step."""

    hit: np.ndarray  # [n] bool
    s: np.ndarray  # [n] time of impact in [0, 1] (fraction of the step)
    normal: np.ndarray  # [n, 3] unit, from the surface towards the body
    depth0: np.ndarray  # [n] penetration at the start of the step (m), usually 0


def _no_hits(n: int) -> Hits:
    return Hits(np.zeros(n, dtype=bool), np.zeros(n), np.zeros((n, 3)), np.zeros(n))


@dataclass
class Collider:
    """A collision surface with its material (restitution, kinetic and static friction);
    `motion` (kinematic.ColliderMotion) when it moves: its geometry here is then its
    reference pose, and sweep_collider sweeps bodies in that frame."""

    name: str
    restitution: float
    friction: float
    static_friction: float
    motion: Any = None

    def sweep(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """Bodies of radius r [n] whose centres move x0 -> x1 ([n, 3]) over the step,
        against this surface: who hits it, when, the normal and the start penetration."""
        raise NotImplementedError


def sweep_collider(col: Collider, x0: np.ndarray, x1: np.ndarray, r: np.ndarray, t: float, t1: float) -> Hits:
    """`col.sweep` over the step t -> t1; for a moving collider, in its reference frame
    (kinematic.py): the centres move from G(t)^-1 x0 to G(t1)^-1 x1 relative to it, and
    the normals come back to world space at t1."""
    m = col.motion
    if m is None:
        return col.sweep(x0, x1, r)
    hits = col.sweep(m.to_reference(t, x0), m.to_reference(t1, x1), r)
    if m.outside_only:  # (a body seen by particles: one born inside it is left to leave it)
        hits.hit &= hits.depth0 <= 0
    if hits.hit.any():
        hits.normal = m.direction_to_world(t1, hits.normal)
    return hits


@dataclass
class PlaneCollider(Collider):
    """A two-sided rectangle (half sizes half_u, half_v along axes u, v) or disk
    (disk_radius) through `point` with unit `normal`; half sizes inf for an infinite plane."""

    point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    u: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    v: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    half_u: float = np.inf
    half_v: float = np.inf
    disk_radius: float | None = None

    def sweep(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray, side_from: np.ndarray | None = None) -> Hits:
        """The plane is two-sided: the side of `side_from` (default x0) is the outside,
        e.g. a body's centre when x0 are points on its surface.

        Big groups (100k particles) are screened first, in a few passes over memory,
        with a margin far above rounding: the exact test below runs on the few bodies
        near the plane, so the hits are the same as testing every body."""
        if len(x0) > _SCREEN_FROM:
            near = self._near(x0, x1, r, side_from)
            out = _no_hits(len(x0))
            if near.size:
                h = self._sweep_exact(x0[near], x1[near], r[near], None if side_from is None else side_from[near])
                out.hit[near], out.s[near], out.normal[near], out.depth0[near] = h.hit, h.s, h.normal, h.depth0
            return out
        return self._sweep_exact(x0, x1, r, side_from)

    def _near(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray, side_from: np.ndarray | None) -> np.ndarray:
        """Indices of the bodies that may end the step less than r + TOL from the plane on
        their outside's far side, or start on it (their side in doubt)."""
        offset = float(self.point @ self.normal)
        start = x0 if side_from is None else side_from
        # x @ n - p @ n rounds differently from (x - p) @ n, by ~1e-16 of the coordinates
        scale = 1.0 + abs(offset) + float(np.abs(start).max(initial=0.0)) + float(np.abs(x1).max(initial=0.0))
        margin = 1e-9 * scale
        ref = start @ self.normal
        ref -= offset
        sd1 = x1 @ self.normal
        sd1 -= offset
        outside = np.where(ref >= 0, sd1, -sd1)  # signed distance of the end, outside > 0
        return np.flatnonzero((outside < r - TOL + margin) | (np.abs(ref) <= margin))

    def _sweep_exact(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray, side_from: np.ndarray | None) -> Hits:
        sd0 = (x0 - self.point) @ self.normal
        sd1 = (x1 - self.point) @ self.normal
        ref = sd0 if side_from is None else (side_from - self.point) @ self.normal
        side = np.where(ref >= 0, 1.0, -1.0)
        d0 = side * sd0 - r  # surface distance: > 0 apart, < 0 penetrating
        d1 = side * sd1 - r
        if not (d1 < -TOL).any():  # nobody ends the step inside: no hit (most steps)
            return _no_hits(len(x0))
        # d(s) is linear along the segment: d0 + s (d1 - d0) = 0
        s = np.where(d0 > 0, d0 / np.where(d0 - d1 != 0, d0 - d1, 1.0), 0.0)
        point = x0 + s[:, None] * (x1 - x0) - self.point
        pu, pv = point @ self.u, point @ self.v
        if self.disk_radius is not None:
            inside = pu * pu + pv * pv <= self.disk_radius**2
        else:
            inside = (np.abs(pu) <= self.half_u) & (np.abs(pv) <= self.half_v)
        hit = (d1 < -TOL) & inside
        return Hits(hit, np.clip(s, 0.0, 1.0), side[:, None] * self.normal[None, :], np.maximum(-d0, 0.0))


@dataclass
class SphereCollider(Collider):
    """A solid sphere of `radius` (m) about `center`."""

    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    radius: float = 1.0

    def sweep(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """Segments against the sphere grown by r (a quadratic in the step fraction)."""
        return _sweep_spheres(x0 - self.center, x1 - self.center, self.radius + r)


def _sweep_spheres(p0: np.ndarray, p1: np.ndarray, reach: np.ndarray) -> Hits:
    """Segment p0 -> p1 (relative positions) against a sphere of radius `reach` at 0:
    |p0 + s d|^2 = R^2  <=>  a s^2 + b s + c = 0 with a = d.d, b = 2 p0.d, c = p0.p0 - R^2."""
    d = p1 - p0
    a = np.einsum("ij,ij->i", d, d)
    b = 2.0 * np.einsum("ij,ij->i", p0, d)
    c = np.einsum("ij,ij->i", p0, p0) - reach * reach
    dist0 = np.sqrt(np.maximum(np.einsum("ij,ij->i", p0, p0), 0.0))
    inside = c < 0
    disc = b * b - 4.0 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    a_safe = np.where(a > 0, a, 1.0)
    s_in = (-b - root) / (2.0 * a_safe)
    s_out = (-b + root) / (2.0 * a_safe)
    entering = (~inside) & (a > 0) & (disc > 0) & (b < 0) & (s_in >= 0) & (s_in < 1) & ((np.minimum(s_out, 1.0) - s_in) * np.sqrt(a) > TOL)
    s = np.where(inside, 0.0, np.clip(s_in, 0.0, 1.0))
    at = p0 + s[:, None] * d
    norm = np.linalg.norm(at, axis=1)
    fallback = np.zeros_like(at)
    fallback[:, 1] = 1.0  # coincident centres: separate along +Y
    normal = np.where(norm[:, None] > 0, at / np.where(norm > 0, norm, 1.0)[:, None], fallback)
    return Hits(inside | entering, s, normal, np.where(inside, reach - dist0, 0.0))


@dataclass
class BoxCollider(Collider):
    """An oriented box: centre, rotation (world_from_local, 3x3) and half extents (m)."""

    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    half: np.ndarray = field(default_factory=lambda: np.full(3, 0.5))

    def sweep(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """Segments against the box grown by r (slab test in the box frame)."""
        # slab test in the box frame against the box grown by r (corners square, not rounded)
        p0 = (x0 - self.center) @ self.rotation
        p1 = (x1 - self.center) @ self.rotation
        d = p1 - p0
        e = self.half[None, :] + r[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (-e - p0) / d
            tb = (e - p0) / d
        still = d == 0
        t_near = np.where(still, np.where(np.abs(p0) <= e, -np.inf, np.inf), np.minimum(ta, tb))
        t_far = np.where(still, np.where(np.abs(p0) <= e, np.inf, -np.inf), np.maximum(ta, tb))
        axis = np.argmax(t_near, axis=1)
        rows = np.arange(len(p0))
        t_enter = t_near[rows, axis]
        t_exit = np.min(t_far, axis=1)
        inside = np.all(np.abs(p0) < e, axis=1)
        seg = np.linalg.norm(d, axis=1)
        with np.errstate(invalid="ignore"):
                entering = (~inside) & (t_enter <= t_exit) & (t_enter >= 0) & (t_enter < 1) & ((np.minimum(t_exit, 1.0) - t_enter) * seg > TOL)
        # inside at the start: leave through the face of least penetration
        pen = e - np.abs(p0)
        in_axis = np.argmin(pen, axis=1)
        use_axis = np.where(inside, in_axis, axis)
        sign = np.where(inside, np.sign(p0[rows, in_axis]), -np.sign(d[rows, axis]))
        sign = np.where(sign == 0, 1.0, sign)
        n_local = np.zeros_like(p0)
        n_local[rows, use_axis] = sign
        s = np.where(inside, 0.0, np.clip(np.nan_to_num(t_enter, neginf=0.0, posinf=1.0), 0.0, 1.0))
        return Hits(inside | entering, s, n_local @ self.rotation.T, np.where(inside, pen[rows, in_axis], 0.0))


@dataclass
class MeshCollider(Collider):
    """A triangle mesh in world space ([m, 3, 3]); two-sided. A body's sphere is swept
    against each triangle's face (centre over the triangle), each edge (the cylinder of
    radius r about the segment) and each vertex (the sphere of radius r about it): the
    mesh grown by r with rounded edges and corners, so a ball dropped on a ridge or a
    corner lands on it instead of passing between the faces. Faces win ties with the
    edges and vertices they border (a ball on a flat mesh over an inner edge has the
    face's normal)."""

    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))

    def __post_init__(self) -> None:
        a, b, c = self.triangles[:, 0], self.triangles[:, 1], self.triangles[:, 2]
        n = cross(b - a, c - a)
        length = np.linalg.norm(n, axis=1)
        keep = length > 1e-15
        self.triangles = self.triangles[keep]
        self._n = n[keep] / length[keep, None]
        self._a = self.triangles[:, 0]
        self._e1 = self.triangles[:, 1] - self._a
        self._e2 = self.triangles[:, 2] - self._a
        d00 = np.einsum("ij,ij->i", self._e1, self._e1)
        d01 = np.einsum("ij,ij->i", self._e1, self._e2)
        d11 = np.einsum("ij,ij->i", self._e2, self._e2)
        self._dots = (d00, d01, d11, d00 * d11 - d01 * d01)
        # each edge and vertex once (shared by neighbouring triangles), by exact coordinates
        points, index = np.unique(self.triangles.reshape(-1, 3), axis=0, return_inverse=True)
        corners = index.reshape(-1, 3)
        pairs = np.sort(np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]]), axis=1)
        pairs = np.unique(pairs, axis=0) if len(pairs) else pairs.reshape(0, 2)
        self._vertices = points
        self._edge_p = points[pairs[:, 0]]
        edge = points[pairs[:, 1]] - self._edge_p
        self._edge_len = np.linalg.norm(edge, axis=1)
        self._edge_dir = edge / np.where(self._edge_len > 0, self._edge_len, 1.0)[:, None]

    def sweep(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """Segments against the mesh grown by r (faces, edges, vertices); the earliest hit
        counts."""
        out = _no_hits(len(x0))
        m = len(self.triangles)
        if m == 0 or len(x0) == 0:
            return out
        chunk = max(1, _MESH_CHUNK // (m + len(self._edge_p) + len(self._vertices)))
        for lo in range(0, len(x0), chunk):
            sl = slice(lo, lo + chunk)
            h = self._sweep_chunk(x0[sl], x1[sl], r[sl])
            for other in (self._sweep_edges(x0[sl], x1[sl], r[sl]), self._sweep_vertices(x0[sl], x1[sl], r[sl])):
                first = other.hit & (~h.hit | (other.s < h.s))  # strictly earlier: faces win ties
                h.hit |= first
                h.s = np.where(first, other.s, h.s)
                h.normal = np.where(first[:, None], other.normal, h.normal)
                h.depth0 = np.where(first, other.depth0, h.depth0)
            out.hit[sl], out.s[sl], out.normal[sl], out.depth0[sl] = h.hit, h.s, h.normal, h.depth0
        return out

    def _sweep_chunk(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        n_t, a = self._n, self._a
        sd0 = np.einsum("bk,tk->bt", x0, n_t) - np.einsum("tk,tk->t", a, n_t)[None, :]
        sd1 = np.einsum("bk,tk->bt", x1, n_t) - np.einsum("tk,tk->t", a, n_t)[None, :]
        side = np.where(sd0 >= 0, 1.0, -1.0)
        d0 = side * sd0 - r[:, None]
        d1 = side * sd1 - r[:, None]
        s = np.where(d0 > 0, d0 / np.where(d0 - d1 != 0, d0 - d1, 1.0), 0.0)
        s = np.clip(s, 0.0, 1.0)
        # centre at impact, projected onto the triangle's plane, in barycentric coordinates
        centre = x0[:, None, :] + s[..., None] * (x1 - x0)[:, None, :]
        sd = np.einsum("btk,tk->bt", centre - a[None], n_t)
        rel = centre - a[None] - sd[..., None] * n_t[None]
        d00, d01, d11, den = self._dots
        d20 = np.einsum("btk,tk->bt", rel, self._e1)
        d21 = np.einsum("btk,tk->bt", rel, self._e2)
        den = np.where(den != 0, den, 1.0)
        bv = (d11 * d20 - d01 * d21) / den
        bw = (d00 * d21 - d01 * d20) / den
        over = (bv >= -1e-9) & (bw >= -1e-9) & (bv + bw <= 1 + 1e-9)
        near = side * sd0 > -r[:, None]  # not already past the plane's far side by a radius
        valid = (d1 < -TOL) & over & near
        key = np.where(valid, s, np.inf)
        best = np.argmin(key, axis=1)
        rows = np.arange(len(x0))
        hit = np.isfinite(key[rows, best])
        normal = side[rows, best][:, None] * n_t[best]
        return Hits(hit, s[rows, best], normal, np.maximum(-d0[rows, best], 0.0))

    def _sweep_edges(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """The centres' segments against the cylinders of radius r about the edges: the
        distance to the edge's line, |m + s n|, with the parts of (x0 - p) and of the step d
        across the edge, reaches r where a s^2 + b s + c = 0; the contact counts where the
        centre is then alongside the edge (beyond its ends is a vertex's) and the segment
        runs inside the cylinder for more than TOL (as sphere colliders). Only the (body,
        edge) pairs whose bounding spheres meet are tested (`_near_pairs`)."""
        e_all, length_all = self._edge_dir, self._edge_len
        bi, ei = _near_pairs(x0, x1, r, self._edge_p + 0.5 * length_all[:, None] * e_all, 0.5 * length_all)
        if bi.size == 0:
            return _no_hits(len(x0))
        e, p, length = e_all[ei], self._edge_p[ei], length_all[ei]
        w0 = x0[bi] - p
        d = x1[bi] - x0[bi]
        along0 = np.einsum("ik,ik->i", w0, e)
        along_d = np.einsum("ik,ik->i", d, e)
        m = w0 - along0[:, None] * e
        n = d - along_d[:, None] * e
        a = np.einsum("ik,ik->i", n, n)
        b = 2.0 * np.einsum("ik,ik->i", m, n)
        mm = np.einsum("ik,ik->i", m, m)
        c = mm - r[bi] ** 2
        disc = b * b - 4.0 * a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        a_safe = np.where(a > 0, a, 1.0)
        s_in = (-b - root) / (2.0 * a_safe)
        s_out = (-b + root) / (2.0 * a_safe)
        inside = c < 0
        entering = (~inside) & (a > 0) & (disc > 0) & (b < 0) & (s_in >= 0) & (s_in < 1) & ((np.minimum(s_out, 1.0) - s_in) * np.sqrt(a) > TOL)
        s = np.where(inside, 0.0, np.clip(s_in, 0.0, 1.0))
        along = along0 + s * along_d
        valid = (inside | entering) & (along >= 0) & (along <= length)
        centre = x0[bi] + s[:, None] * d
        normal = _unit_or_up(centre - (p + along[:, None] * e))
        depth0 = np.where(inside, r[bi] - np.sqrt(mm), 0.0)
        return _earliest(len(x0), bi, valid, s, normal, depth0)

    def _sweep_vertices(self, x0: np.ndarray, x1: np.ndarray, r: np.ndarray) -> Hits:
        """The centres' segments against the spheres of radius r about the vertices (only
        the pairs whose bounding spheres meet)."""
        bi, vi = _near_pairs(x0, x1, r, self._vertices, np.zeros(len(self._vertices)))
        if bi.size == 0:
            return _no_hits(len(x0))
        hits = _sweep_spheres(x0[bi] - self._vertices[vi], x1[bi] - self._vertices[vi], r[bi])
        return _earliest(len(x0), bi, hits.hit, hits.s, hits.normal, hits.depth0)


def _near_pairs(x0: np.ndarray, x1: np.ndarray, r: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(body, feature) index pairs whose bounding spheres meet: the body's segment grown by
    its radius (about the segment's middle) and the feature's (an edge's about its
    middle, a vertex's of radius 0), with a margin far above rounding."""
    if len(centres) == 0 or len(x0) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    mid = 0.5 * (x0 + x1)
    reach = 0.5 * np.linalg.norm(x1 - x0, axis=1) + r
    # |mid - c|^2 by its expansion (one matrix product), checked with a margin
    d2 = np.einsum("ij,ij->i", mid, mid)[:, None] - 2.0 * (mid @ centres.T) + np.einsum("ij,ij->i", centres, centres)[None, :]
    scale = 1.0 + float(np.abs(mid).max()) + float(np.abs(centres).max())
    limit = reach[:, None] + radii[None, :] + 1e-6 * scale
    return np.nonzero(d2 <= limit * limit)


def _earliest(count: int, body: np.ndarray, valid: np.ndarray, s: np.ndarray, normal: np.ndarray, depth0: np.ndarray) -> Hits:
    """Per body (of `count`), the earliest valid contact among its candidate pairs."""
    out = _no_hits(count)
    keep = np.flatnonzero(valid)
    if keep.size == 0:
        return out
    order = keep[np.lexsort((s[keep], body[keep]))]  # by body, then by time of impact
    first = order[np.unique(body[order], return_index=True)[1]]
    who = body[first]
    out.hit[who], out.s[who], out.normal[who], out.depth0[who] = True, s[first], normal[first], depth0[first]
    return out


def _unit_or_up(v: np.ndarray) -> np.ndarray:
    """Rows of v made unit length; +Y where a row is zero (a centre exactly on an edge)."""
    norm = np.linalg.norm(v, axis=1)
    up = np.zeros_like(v)
    up[:, 1] = 1.0
    return np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None], up)


@dataclass
class ContactBodies:
    """The step's body arrays, changed in place by the resolution (views are fine)."""

    x0: np.ndarray
    v0: np.ndarray
    x1: np.ndarray
    v1: np.ndarray
    w1: np.ndarray | None  # angular velocity at the end of the step (rigid groups)
    inv_inertia_world: np.ndarray | None  # [n, 3, 3]
    radius: np.ndarray
    inv_mass: np.ndarray  # 0: pinned or not moving this step
    restitution: np.ndarray
    friction: np.ndarray
    static_friction: np.ndarray


@dataclass
class Impacts:
    """Impacts found in one step: body index, fraction of the step, approach speed (m/s),
    what was hit (collider name or the other body's index as a string)."""

    body: list[np.ndarray] = field(default_factory=list)
    s: list[np.ndarray] = field(default_factory=list)
    speed: list[np.ndarray] = field(default_factory=list)
    other: list[np.ndarray] = field(default_factory=list)


def _apply_friction(b: ContactBodies, idx: np.ndarray, n: np.ndarray, normal_impulse: np.ndarray, mu: np.ndarray, mu_s: np.ndarray, lever: np.ndarray,
                    surface: np.ndarray | None = None) -> np.ndarray:
    """Coulomb friction impulse at the contact point r = -radius n of bodies idx against a
    static surface (see module docstring). The position moves by lever * dv: friction acts
    over the contact part of the step, (1 - s) h, as a constant deceleration (trapezoid:
    lever = (1 - s) h / 2), so a sticking contact does not creep."""
    inv_m = b.inv_mass[idx]
    r_c = -b.radius[idx, None] * n
    u = b.v1[idx] if surface is None else b.v1[idx] - surface
    if b.w1 is not None:
        u = u + cross(b.w1[idx], r_c)
    u_t = u - np.einsum("ij,ij->i", u, n)[:, None] * n
    slip = np.linalg.norm(u_t, axis=1)
    t_hat = u_t / np.where(slip > 0, slip, 1.0)[:, None]
    k_t = inv_m.copy()
    if b.inv_inertia_world is not None:
        rxt = cross(r_c, t_hat)
        k_t += np.einsum("ij,ij->i", cross(np.einsum("nij,nj->ni", b.inv_inertia_world[idx], rxt), r_c), t_hat)
    jt = coulomb_friction(slip, normal_impulse, k_t, mu, mu_s)
    dv = -(jt * inv_m)[:, None] * t_hat
    b.v1[idx] += dv
    b.x1[idx] += lever[:, None] * dv
    if b.w1 is not None and b.inv_inertia_world is not None:
        b.w1[idx] -= np.einsum("nij,nj->ni", b.inv_inertia_world[idx], cross(r_c, jt[:, None] * t_hat))
    return -jt[:, None] * t_hat


def resolve_static(b: ContactBodies, hits: Hits, col: Collider, h: float, v_rest: float, t: float = 0.0) -> np.ndarray:
    """Impulse response of the bodies that hit `col` this step (in place). Returns [6, k]:
    the bodies whose contact was an impact (approach faster than v_rest), their approach
    speeds (m/s), times of impact (fraction of the step) and centres at impact (x, y, z).
    A moving collider (its motion over the step that starts at `t`) takes part with its
    own velocity u(x) at the contact: every normal velocity is relative to it, v - u."""
    idx = np.flatnonzero(hits.hit & (b.inv_mass > 0))
    if idx.size == 0:
        return np.zeros((6, 0))
    m = col.motion
    s = hits.s[idx][:, None]
    n = hits.normal[idx]
    x0, x1, v0, v1 = b.x0[idx], b.x1[idx], b.v0[idx], b.v1[idx]
    xc = x0 + s * (x1 - x0)
    v_c = v0 + s * (v1 - v0)
    dv = v1 - v0
    if m is not None:  # the surface's velocity at the contact, at the time of impact
        w_lin, w_ang, origin = m.rates(t)
        u_c = w_lin + cross(np.broadcast_to(w_ang, xc.shape), xc - (origin + s * h * w_lin))
        vn = np.einsum("ij,ij->i", v_c - u_c, n)
    else:
        vn = np.einsum("ij,ij->i", v_c, n)
    approaching = vn < 0
    impact = -vn > v_rest
    eps = np.where(impact, np.minimum(b.restitution[idx], col.restitution), 0.0)
    # j = -(1 + eps) m v.n  ->  velocity change -(1 + eps) v.n along n
    dvn = np.where(approaching, -(1.0 + eps) * vn, 0.0)
    v_post = v_c + dvn[:, None] * n
    v_end = v_post + (1.0 - s) * dv
    x_end = xc + (1.0 - s) * h * 0.5 * (v_post + v_end)
    # resting contact: back onto the contact surface, normal velocity clamped to >= 0
    if m is None:
        lift = np.einsum("ij,ij->i", xc - x_end, n) + hits.depth0[idx]
    else:  # in the collider's frame, where the contact point stays on its surface
        y0, y1 = m.to_reference(t, x0), m.to_reference(t + h, x1)
        n_ref = n @ m.at(t + h)[0]
        lift = np.einsum("ij,ij->i", y0 + s * (y1 - y0) - m.to_reference(t + h, x_end), n_ref) + hits.depth0[idx]
    supported = lift >= 0
    x_end += np.maximum(lift, 0.0)[:, None] * n
    u_end = None if m is None else m.velocity(t + h, x_end, t)
    vn_end = np.einsum("ij,ij->i", v_end if u_end is None else v_end - u_end, n)
    support = np.where(supported & (vn_end < 0), -vn_end, 0.0)
    v_end += support[:, None] * n
    b.x1[idx] = x_end
    b.v1[idx] = v_end
    normal_impulse = (dvn + support) / b.inv_mass[idx]
    mu = np.sqrt(b.friction[idx] * col.friction)
    mu_s = np.sqrt(b.static_friction[idx] * col.static_friction)
    friction = _apply_friction(b, idx, n, normal_impulse, mu, mu_s, 0.5 * (1.0 - s[:, 0]) * h, u_end)
    if m is not None:  # the work the surface did (impulse . its velocity), for the guard
        push = normal_impulse[:, None] * n + friction
        m.work += float(np.maximum(np.einsum("ij,ij->i", push, u_c), 0.0).sum())
    return np.concatenate((np.stack((idx[impact].astype(np.float64), -vn[impact], hits.s[idx][impact])), xc[impact].T))


def resolve_pairs(b: ContactBodies, pairs: tuple[np.ndarray, np.ndarray], h: float, v_rest: float) -> np.ndarray:
    """Sphere-sphere impulses between body pairs (i, j), all pairs at once (Jacobi).
    Returns [6, k]: body i, body j, approach speed, centre of i at the impact (x, y, z)."""
    i, j = pairs
    if i.size == 0:
        return np.zeros((6, 0))
    reach = b.radius[i] + b.radius[j]
    p0, p1 = b.x0[i] - b.x0[j], b.x1[i] - b.x1[j]
    # broad phase: along the segment |p0 + s d| >= |p0| - |d|, so no pair with
    # |p0| > reach + |d| can touch this step (most pairs, most steps)
    d = p1 - p0
    near = np.einsum("ij,ij->i", p0, p0) <= (reach + np.sqrt(np.einsum("ij,ij->i", d, d)) + TOL) ** 2
    if not near.any():
        return np.zeros((6, 0))
    hits = _sweep_spheres(p0, p1, reach)
    k = np.flatnonzero(hits.hit & ((b.inv_mass[i] + b.inv_mass[j]) > 0))
    if k.size == 0:
        return np.zeros((6, 0))
    i, j, n, s = i[k], j[k], hits.normal[k], hits.s[k]
    inv_i, inv_j = b.inv_mass[i], b.inv_mass[j]
    x_hit = b.x0[i] + s[:, None] * (b.x1[i] - b.x0[i])
    v_rel = b.v1[i] - b.v1[j]
    vn = np.einsum("ij,ij->i", v_rel, n)
    approaching = vn < 0
    impact = -vn > v_rest
    eps = np.where(impact, np.minimum(b.restitution[i], b.restitution[j]), 0.0)
    # (v_rel + J (1/m_i + 1/m_j) n) . n = -eps v_rel . n
    J = np.where(approaching, -(1.0 + eps) * vn / (inv_i + inv_j), 0.0)
    dv_i = (J * inv_i)[:, None] * n
    dv_j = -(J * inv_j)[:, None] * n
    # friction on the relative slip at the contact point (r_i = -R_i n, r_j = R_j n)
    r_i, r_j = -b.radius[i, None] * n, b.radius[j, None] * n
    u = (b.v1[i] + dv_i) - (b.v1[j] + dv_j)
    if b.w1 is not None:
        u = u + cross(b.w1[i], r_i) - cross(b.w1[j], r_j)
    u_t = u - np.einsum("ij,ij->i", u, n)[:, None] * n
    slip = np.linalg.norm(u_t, axis=1)
    t_hat = u_t / np.where(slip > 0, slip, 1.0)[:, None]
    k_t = inv_i + inv_j
    if b.inv_inertia_world is not None:
        for idx, r in ((i, r_i), (j, r_j)):
            rxt = cross(r, t_hat)
            k_t = k_t + np.einsum("ij,ij->i", cross(np.einsum("nij,nj->ni", b.inv_inertia_world[idx], rxt), r), t_hat)
    mu = np.sqrt(b.friction[i] * b.friction[j])
    mu_s = np.sqrt(b.static_friction[i] * b.static_friction[j])
    jt = coulomb_friction(slip, J, k_t, mu, mu_s)
    dv_i -= (jt * inv_i)[:, None] * t_hat
    dv_j += (jt * inv_j)[:, None] * t_hat
    np.add.at(b.v1, i, dv_i)
    np.add.at(b.v1, j, dv_j)
    # the rest of the step moves with the changed velocities
    np.add.at(b.x1, i, (1.0 - s)[:, None] * h * dv_i)
    np.add.at(b.x1, j, (1.0 - s)[:, None] * h * dv_j)
    if b.w1 is not None and b.inv_inertia_world is not None:
        imp = -jt[:, None] * t_hat
        np.add.at(b.w1, i, np.einsum("nij,nj->ni", b.inv_inertia_world[i], cross(r_i, imp)))
        np.add.at(b.w1, j, np.einsum("nij,nj->ni", b.inv_inertia_world[j], cross(r_j, -imp)))
    # remove the overlap left, in the ratio of inverse masses (centre of mass unchanged)
    d = b.x1[i] - b.x1[j]
    dist = np.linalg.norm(d, axis=1)
    overlap = np.maximum(reach[k] - dist, 0.0)
    n_end = np.where(dist[:, None] > 0, d / np.where(dist > 0, dist, 1.0)[:, None], n)
    share = overlap / (inv_i + inv_j)
    np.add.at(b.x1, i, (share * inv_i)[:, None] * n_end)
    np.add.at(b.x1, j, -(share * inv_j)[:, None] * n_end)
    return np.concatenate((np.stack((i[impact].astype(np.float64), j[impact].astype(np.float64), -vn[impact])), x_hit[impact].T))
