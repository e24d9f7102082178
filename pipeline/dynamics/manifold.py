"""Contact manifolds between two boxes: the separating axis test on the 15 axes, then the
clipped incident face (up to 4 points) or the closest points of two edges (1 point).

Boxes A and B (centres c, rotations R whose columns are the box axes, half extents h). For an
axis L the boxes' projections are separated by
    s(L) = |d . L| - (sum_k h_A,k |a_k . L| + sum_k h_B,k |b_k . L|),   d = c_B - c_A,
with L one of A's 3 face normals, B's 3, or the 9 cross products a_i x b_j (skipped when
nearly parallel). The axis of largest s is the contact normal (s > 0: a gap). Face axes are
preferred over edge axes unless an edge separates clearly more (a small tolerance), and A's
faces over B's likewise, so a resting face contact keeps the same reference face from step
to step (the manifold does not flicker). The same choice as Box2D's and Bullet's box-box.

Face contact: the reference face is the box's face along the normal; the incident face is
the other box's face most opposed to it. The incident face's 4 corners are clipped by the
reference face's 4 side planes (Sutherland-Hodgman); each point p left keeps its separation
s_p = n . (p - f) from the reference face's plane (f a point on it), and the contact pair is
(p on the incident box, p - s_p n on the reference face). More than 4 points are reduced to
4 spread over the patch (the deepest, the farthest from it, then the two that span most area).

Edge contact: the two boxes' edges along a_i and b_j that lie furthest towards each other
along n; the contact pair is their closest points.
"""

from __future__ import annotations

import numpy as np

FACE_TOLERANCE = 0.02  # of the smaller box's least half extent: a face axis wins ties
_PARALLEL = 1e-6  # |a_i x b_j| below this: the edge axis is skipped (a face axis covers it)


def _separations(d: np.ndarray, ra: np.ndarray, ha: np.ndarray, rb: np.ndarray, hb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For P pairs ([P, 3] centre offsets, [P, 3, 3] rotations, [P, 3] half extents): s(L) on
    A's face axes and B's [P, 6], on the 9 edge axes [P, 9] (-inf when skipped), and the
    unit edge axes [P, 9, 3]."""
    c = np.einsum("pki,pkj->pij", ra, rb)  # c_ij = a_i . b_j
    abs_c = np.abs(c) + 1e-15
    face_a = np.abs(np.einsum("pki,pk->pi", ra, d)) - (ha + np.einsum("pij,pj->pi", abs_c, hb))
    face_b = np.abs(np.einsum("pkj,pk->pj", rb, d)) - (hb + np.einsum("pij,pi->pj", abs_c, ha))
    a_ax, b_ax = np.swapaxes(ra, 1, 2), np.swapaxes(rb, 1, 2)  # rows: the axes
    axes = np.cross(a_ax[:, :, None, :], b_ax[:, None, :, :]).reshape(-1, 9, 3)
    norm = np.linalg.norm(axes, axis=2)
    ok = norm > _PARALLEL
    axes = axes / np.where(ok, norm, 1.0)[..., None]
    proj = np.einsum("pek,pk->pe", np.abs(np.einsum("pej,pjk->pek", axes, ra)), ha) + np.einsum("pek,pk->pe", np.abs(np.einsum("pej,pjk->pek", axes, rb)), hb)
    edge = np.where(ok, np.abs(np.einsum("pej,pj->pe", axes, d)) - proj, -np.inf)
    return np.concatenate((face_a, face_b), axis=1), edge, axes


def _clip(poly: np.ndarray, axis: np.ndarray, offset: float) -> np.ndarray:
    """The part of a polygon [k, 3] with p . axis <= offset (one Sutherland-Hodgman plane)."""
    dist = poly @ axis - offset
    out = []
    k = len(poly)
    for i in range(k):
        p, q = poly[i], poly[(i + 1) % k]
        dp, dq = dist[i], dist[(i + 1) % k]
        if dp <= 0:
            out.append(p)
        if (dp < 0 < dq) or (dq < 0 < dp):
            out.append(p + (dp / (dp - dq)) * (q - p))
    return np.array(out).reshape(-1, 3)


def _reduce(points: np.ndarray, sep: np.ndarray) -> np.ndarray:
    """Indices of at most 4 points spread over the patch: the deepest, the farthest from it,
    then the points furthest to either side of the line through those two."""
    if len(points) <= 4:
        return np.arange(len(points))
    first = int(np.argmin(sep))
    second = int(np.argmax(np.linalg.norm(points - points[first], axis=1)))
    line = points[second] - points[first]
    normal = np.cross(line, np.cross(points - points[first], line).sum(axis=0))
    side = (points - points[first]) @ normal if np.linalg.norm(normal) > 0 else np.zeros(len(points))
    chosen = [first, second, int(np.argmax(side)), int(np.argmin(side))]
    return np.array(sorted(set(chosen)))


def _face_contact(c_ref: np.ndarray, r_ref: np.ndarray, h_ref: np.ndarray, c_inc: np.ndarray, r_inc: np.ndarray, h_inc: np.ndarray,
                  axis: int, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference face of box `ref` along its `axis`, towards the incident box. Returns the
    normal (ref -> inc), the points on the reference face [k, 3], on the incident box [k, 3]
    and their separations [k]."""
    n = r_ref[:, axis] * (1.0 if (c_inc - c_ref) @ r_ref[:, axis] >= 0 else -1.0)
    along = r_inc.T @ n
    j = int(np.argmax(np.abs(along)))
    face_n = -np.sign(along[j]) * r_inc[:, j] if along[j] != 0 else r_inc[:, j]
    u, v = (j + 1) % 3, (j + 2) % 3
    centre = c_inc + h_inc[j] * face_n
    eu, ev = h_inc[u] * r_inc[:, u], h_inc[v] * r_inc[:, v]
    poly = np.stack((centre + eu + ev, centre - eu + ev, centre - eu - ev, centre + eu - ev))
    sides = [(axis + 1) % 3, (axis + 2) % 3]
    # corners within 1 nm of the reference face's sides are inside (an aligned stack's
    # equal faces: no clipping, the 4 corners are the manifold)
    inside = np.abs((poly - c_ref) @ r_ref[:, sides]) <= h_ref[sides] + 1e-9
    for side in sides if not inside.all() else ():
        t = r_ref[:, side]
        off = t @ c_ref
        poly = _clip(poly, t, off + h_ref[side])
        poly = _clip(poly, -t, -off + h_ref[side])
        if len(poly) == 0:
            return n, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    face = c_ref + h_ref[axis] * n
    sep = (poly - face) @ n
    keep = sep <= margin
    poly, sep = poly[keep], sep[keep]
    pick = _reduce(poly, sep)
    poly, sep = poly[pick], sep[pick]
    return n, poly - sep[:, None] * n, poly, sep


def _edge_contact(ca: np.ndarray, ra: np.ndarray, ha: np.ndarray, cb: np.ndarray, rb: np.ndarray, hb: np.ndarray, i: int, j: int,
                  n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of A's edge along a_i furthest towards B (along n) and B's edge along b_j
    furthest towards A."""
    sa = np.where(ra.T @ n >= 0, 1.0, -1.0) * ha
    sb = np.where(rb.T @ n >= 0, -1.0, 1.0) * hb
    sa[i], sb[j] = 0.0, 0.0
    pa, pb = ca + ra @ sa, cb + rb @ sb
    ea, eb = ha[i] * ra[:, i], hb[j] * rb[:, j]
    # closest points of the segments pa +- ea, pb +- eb (the lines, clamped to the segments)
    w = pa - pb
    a, b, c = ea @ ea, ea @ eb, eb @ eb
    d, e = ea @ w, eb @ w
    den = a * c - b * b
    s = np.clip((b * e - c * d) / den, -1.0, 1.0) if den > 1e-300 else 0.0
    t = np.clip((b * s + e) / c, -1.0, 1.0)
    s = np.clip((b * t - d) / a, -1.0, 1.0)
    return pa + s * ea, pb + t * eb


def manifolds(ca: np.ndarray, ra: np.ndarray, ha: np.ndarray, cb: np.ndarray, rb: np.ndarray, hb: np.ndarray,
              margin: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None]:
    """The contact manifolds of P box pairs A, B (world centres [P, 3], rotations [P, 3, 3],
    half extents [P, 3]): per pair None when they are more than `margin` apart, else the unit
    normal from A to B, the contact points on A [k, 3] and on B [k, 3] (k <= 4) and the
    separations (p_B - p_A) . n [k] (< 0: penetrating)."""
    d = cb - ca
    faces, edges, axes = _separations(d, ra, ha, rb, hb)
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None] = []
    far = np.maximum(faces.max(axis=1), edges.max(axis=1)) > margin
    for p in range(len(d)):
        out.append(None if far[p] else _one(ca[p], ra[p], ha[p], cb[p], rb[p], hb[p], faces[p], edges[p], axes[p], margin))
    return out


def _one(ca: np.ndarray, ra: np.ndarray, ha: np.ndarray, cb: np.ndarray, rb: np.ndarray, hb: np.ndarray, faces: np.ndarray, edges: np.ndarray,
         axes: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One pair's manifold from its separations (see `manifolds`)."""
    d = cb - ca
    tol = FACE_TOLERANCE * min(ha.min(), hb.min())
    fa, fb = int(np.argmax(faces[:3])), int(np.argmax(faces[3:]))
    best_face = faces[fa] if faces[fa] + tol >= faces[3 + fb] else faces[3 + fb]
    e = int(np.argmax(edges))
    if edges[e] > best_face + tol:
        n = axes[e] if axes[e] @ d >= 0 else -axes[e]
        pa, pb = _edge_contact(ca, ra, ha, cb, rb, hb, e // 3, e % 3, n)
        return n, pa[None], pb[None], np.array([(pb - pa) @ n])
    if faces[fa] + tol >= faces[3 + fb]:
        n, on_ref, on_inc, sep = _face_contact(ca, ra, ha, cb, rb, hb, fa, margin)
        return (n, on_ref, on_inc, sep) if len(sep) else None
    n, on_ref, on_inc, sep = _face_contact(cb, rb, hb, ca, ra, ha, fb, margin)
    return (-n, on_inc, on_ref, sep) if len(sep) else None
