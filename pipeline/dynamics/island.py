"""Contacts solved across bodies: boxes on boxes (and the same boxes' contacts with static
colliders) as one system of sequential impulses, then one position pass.

Used by the collide stage when boxes touch boxes (shapes.py keeps solving each body alone
against static colliders otherwise). The stages, as Box2D's and Bullet's contact solvers:

1. Contacts. Box-box pairs whose bounding spheres come within `margin` of each other get a
   manifold (manifold.py, up to 4 points); the boxes' contacts with static colliders come
   from shapes.find_contacts. Each contact c joins body a (-1: static) and body b, with the
   unit normal n from a to b, points p_a, p_b and the separation s_c = (p_b - p_a) . n.
2. Velocities: projected Gauss-Seidel on the whole set. Rows d in (n, t1, t2) per contact;
   the relative velocity along d is u_d = J_d V, J_d = [-d, -(r_a x d), d, r_b x d] over
   (v_a, w_a, v_b, w_b), and the coupling of two rows is the Delassus matrix
   W = J M^-1 J^T (one dense matrix for the set). Each contact in turn:
   lambda_n <- max(0, lambda_n + (target - u_n) / W_nn) (accumulated, pushes only), then
   the friction pair lambda_t <- lambda_t - u_t / W_tt clamped to the disk mu_s lambda_n
   (sticks) or else mu_k lambda_n (slides), mu = sqrt(mu_a mu_b). The normal target is
   -eps u_n for an impact (approach faster than v_rest, eps = min(eps_a, eps_b)), 0 for a
   resting contact, and -s_c / h for a gap s_c > 0 (a speculative contact: it may close
   the gap within the next step, no more). Contacts run bottom up (static ones first,
   then by height against gravity), which carries a stack's weight down in one sweep.
   Warm start: a static contact by its key (body, point, collider); a box pair's contact
   by the nearest of the pair's contacts of last step (within WARM_DISTANCE, in b's
   frame). A resting stack converges in the first sweep; at most `sweeps` sweeps, ending
   when a sweep changes no contact velocity by more than 1 nm/s. When the warm start is off
   (a first sweep changes a contact velocity by more than 1 um/s: new contacts, a stack's
   first steps) the sweeps start from the direct solve of every row, sticking
   (`_direct_solve`): Gauss-Seidel alone carries a stack's weight down one level per sweep.
3. Positions, as shapes.py: each body moves the rest of the step with its changed
   velocity (half a step for a support, (1 - s) h after an impact at s). Then one pass
   over the contacts, bottom up (shock propagation, Guendelman et al. 2003): a contact's
   separation, linear in the bodies' translations, s_c + n . (dx_b - dx_a), is brought
   back to >= 0 by moving the upper body only (the lower one already rests on what is
   below it; two bodies level with each other share it by inverse mass), along n. So a
   stack that sank by what gravity pulled in during the step is lifted back in one pass,
   every box by the same amount, and stays where it was.
4. Sleeping (`_sleep`), as Box2D's and Bullet's islands: a connected set of touching boxes
   whose bodies have all been calm (slower than SLEEP_SPEED) for SLEEP_TIME is held at rest
   where it fell asleep, until one of them is sped up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import BOX
from ..motion.pose import quat_normalize, quat_to_matrix
from .collisions import ContactBodies
from .manifold import manifolds
from .shapes import Contacts, ShapeSet, _rotate, _tangents

WARM_DISTANCE = 0.1  # of the smaller box's least half extent: a contact of last step this close is the same one
SLEEP_SPEED = 1e-3  # m/s, and SLEEP_SPEED / SLEEP_RADIUS rad/s: slower than this a body is calm
SLEEP_RADIUS = 0.1  # m
SLEEP_TIME = 0.5  # s: a set of touching boxes calm this long sleeps (held where it fell asleep)
CONVERGED = 1e-9  # m/s: a sweep that changes no contact velocity by more is the last
WARM_OFF = 1e-6  # m/s: a first sweep that changes a contact velocity by more: the warm start is off


@dataclass
class Flat:
    """Contacts of one step, one row each: bodies a (-1: static) and b, normal a -> b, the
    points (world, end of step) and in each body's frame (static side: world), separation,
    time of impact (fraction of the step), restitution, friction, what was hit (collider
    index, or -1 - a for a body), and the warm start [C, 3]."""

    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    local_a: np.ndarray
    local_b: np.ndarray
    sep: np.ndarray
    s: np.ndarray
    eps: np.ndarray
    mu: np.ndarray
    mu_s: np.ndarray
    collider: np.ndarray
    lam: np.ndarray
    key: np.ndarray  # static contacts' warm-start keys (-1 for box pairs)


def box_pairs(kind: np.ndarray, movable: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Which body pairs are two boxes solved here (at least one of them movable by impulses)."""
    i, j = pairs
    return (kind[i] == BOX) & (kind[j] == BOX) & (movable[i] | movable[j])


def pair_contacts(b: ContactBodies, shapes: ShapeSet, q1: np.ndarray, i: np.ndarray, j: np.ndarray, margin: float) -> list[tuple[np.ndarray, ...]]:
    """Manifolds of the box pairs (i, j) whose bounding spheres come within `margin`, at the
    end-of-step poses; each pair's rows, warm-started from its contacts of last step."""
    gap = b.x1[i] - b.x1[j]
    reach = b.radius[i] + b.radius[j] + margin
    near = np.flatnonzero(np.einsum("ij,ij->i", gap, gap) <= reach * reach)
    rows: list[tuple[np.ndarray, ...]] = []
    if near.size == 0:
        return rows
    ii, jj = i[near], j[near]
    rot = quat_to_matrix(quat_normalize(q1[np.concatenate((ii, jj))]))
    every = manifolds(b.x1[ii], rot[: near.size], shapes.half[ii], b.x1[jj], rot[near.size:], shapes.half[jj], margin)
    for k, (a, c) in enumerate(zip(ii.tolist(), jj.tolist())):
        ra, rc = rot[k], rot[near.size + k]
        found = every[k]
        if found is None:
            continue
        n, pa, pc, sep = found
        count = len(sep)
        local_a, local_c = (pa - b.x1[a]) @ ra, (pc - b.x1[c]) @ rc
        lam = _pair_warm_start(shapes, (a, c), local_c, min(shapes.half[a].min(), shapes.half[c].min()))
        mu = np.sqrt(b.friction[a] * b.friction[c])
        mu_s = np.sqrt(b.static_friction[a] * b.static_friction[c])
        rows.append((np.full(count, a), np.full(count, c), np.repeat(n[None], count, 0), pa, pc, local_a, local_c, sep, np.ones(count),
                     np.full(count, min(b.restitution[a], b.restitution[c])), np.full(count, mu), np.full(count, mu_s),
                     np.full(count, -1 - a), lam, np.full(count, -1)))
    return rows


def _pair_warm_start(shapes: ShapeSet, pair: tuple[int, int], local: np.ndarray, size: float) -> np.ndarray:
    """Last step's impulses of the pair's contacts nearest to `local` (b's frame), 0 when
    none is within WARM_DISTANCE of the boxes' size."""
    lam = np.zeros((len(local), 3))
    prev = shapes.pair_prev.get(pair)
    if prev is None:
        return lam
    old_local, old_lam = prev
    dist = np.linalg.norm(local[:, None, :] - old_local[None, :, :], axis=2)
    nearest = np.argmin(dist, axis=1)
    close = dist[np.arange(len(local)), nearest] <= WARM_DISTANCE * size
    lam[close] = old_lam[nearest[close]]
    return lam


def static_rows(b: ContactBodies, c: Contacts, shapes: ShapeSet) -> tuple[np.ndarray, ...]:
    """The shaped bodies' contacts with static colliders (shapes.find_contacts) as rows,
    warm-started by key."""
    body = np.broadcast_to(c.body[:, None], c.ok.shape)[c.ok]
    n, depth, lever = c.normal[c.ok], c.depth[c.ok], c.lever[c.ok]
    pb = b.x1[body] + lever
    key = c.key[c.ok]
    lam = np.zeros((body.size, 3))
    if shapes.prev_keys.size:
        at = np.clip(np.searchsorted(shapes.prev_keys, key), 0, shapes.prev_keys.size - 1)
        same = shapes.prev_keys[at] == key
        lam[same] = shapes.prev_lam[at[same]]
    mu = np.sqrt(b.friction[body] * c.mu[c.ok])
    mu_s = np.sqrt(b.static_friction[body] * c.mu_s[c.ok])
    eps = np.minimum(b.restitution[body], c.eps[c.ok])
    return (np.full(body.size, -1), body, n, pb + depth[:, None] * n, pb, pb + depth[:, None] * n, c.local[c.ok], -depth, c.s[c.ok], eps, mu,
            mu_s, c.collider[c.ok], lam, key)


def flatten(rows: list[tuple[np.ndarray, ...]]) -> Flat:
    """One Flat of every row group."""
    return Flat(*(np.concatenate(part) for part in zip(*rows)))


def solve(b: ContactBodies, f: Flat, shapes: ShapeSet, q1: np.ndarray, h: float, v_rest: float, sweeps: int, up: np.ndarray) -> np.ndarray:
    """Impulses, then positions, for the contacts f (in place on b and q1; see the module
    docstring). Returns [7, k]: body, approach speed (m/s), what was hit (collider index, or
    -1 - the other body), time of impact (fraction of the step), centre (x, y, z) of each
    body that had an impact."""
    ids, inv = np.unique(np.concatenate((f.b, f.a[f.a >= 0])), return_inverse=True)
    lb = inv[: f.b.size]
    la = np.full(f.a.size, -1)
    la[f.a >= 0] = inv[f.b.size:]
    order = _bottom_up(f, up)
    J, minv = _jacobian(b, f, ids, la, lb)
    # W = J M^-1 J^T body by body (einsum: tiny products, no threaded BLAS call)
    Jb = J.reshape(J.shape[0], ids.size, 6)
    W = np.einsum("rkl,skl->rs", np.einsum("rkj,kjl->rkl", Jb, minv), Jb)
    V = np.concatenate((b.v1[ids], b.w1[ids] if b.w1 is not None else np.zeros((ids.size, 3))), axis=1).reshape(-1)
    u0 = J @ V
    u0n = u0[0::3]
    impact = -u0n > v_rest
    target = np.where(f.sep > 0, -f.sep / h, 0.0)
    bounce = impact & (f.eps > 0) & (u0n * h + np.maximum(f.sep, 0.0) < 0)
    target = np.where(bounce | (impact & (f.sep <= 0)), -f.eps * np.where(impact, u0n, 0.0), target)
    lam = f.lam.reshape(-1).copy()
    if not _pgs(W, u0, target, f.mu, f.mu_s, lam, order, 1, WARM_OFF):
        # the warm start is off (new contacts, a stack's first steps): start from the direct solve
        lam = f.lam.reshape(-1).copy()
        _direct_solve(W, u0, target, f.mu, lam)
    _pgs(W, u0, target, f.mu, f.mu_s, lam, order, sweeps, CONVERGED)
    dV = np.einsum("kjl,kl->kj", minv, (lam @ J).reshape(-1, 6))
    b.v1[ids] += dV[:, :3]
    if b.w1 is not None:
        b.w1[ids] += dV[:, 3:]
    _store(shapes, f, lam.reshape(-1, 3))
    # positions: the rest of the step after an impact, half of it for a support
    s_hit = np.ones(ids.size)
    np.minimum.at(s_hit, lb[impact], f.s[impact])
    hit_body = s_hit < 1.0
    lever_t = np.where(hit_body, 1.0 - s_hit, 0.5) * h
    b.x1[ids] += lever_t[:, None] * dV[:, :3]
    q1[ids] = _rotate(q1[ids], lever_t[:, None] * dV[:, 3:])
    _lift(b, f, q1, ids, la, lb, order, up)
    _sleep(b, shapes, q1, ids, la, lb, h)
    speed = np.where(impact, -u0n, 0.0)
    hits = np.flatnonzero(impact)
    if hits.size == 0:
        return np.zeros((7, 0))
    first = hits[np.unique(f.b[hits], return_index=True)[1]]
    body = f.b[first]
    return np.concatenate((np.stack((body.astype(np.float64), speed[first], f.collider[first].astype(np.float64), f.s[first])), b.x1[body].T))


def _bottom_up(f: Flat, up: np.ndarray) -> np.ndarray:
    """Contact order: static contacts first, then by the height of the contact point."""
    height = np.einsum("ij,j->i", 0.5 * (f.pa + f.pb), up)
    return np.lexsort((height, f.a >= 0))


def _jacobian(b: ContactBodies, f: Flat, ids: np.ndarray, la: np.ndarray, lb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J [3C, 6N] (rows: contact, direction n, t1, t2; columns: body, v then w) and the
    blocks of the block-diagonal inverse mass matrix M^-1 [N, 6, 6]."""
    C, N = f.b.size, ids.size
    t1, t2 = _tangents(f.normal)
    D = np.stack((f.normal, t1, t2), axis=1)  # [C, 3, 3]
    rb = f.pb - b.x1[f.b]
    ra = np.where((f.a >= 0)[:, None], f.pa - b.x1[np.maximum(f.a, 0)], 0.0)
    J = np.zeros((C, 3, N, 6))
    c = np.arange(C)
    J[c, :, lb, :3] = D
    J[c, :, lb, 3:] = np.cross(rb[:, None, :], D)
    own = np.flatnonzero(f.a >= 0)
    J[own, :, la[own], :3] -= D[own]
    J[own, :, la[own], 3:] -= np.cross(ra[own, None, :], D[own])
    minv = np.zeros((N, 6, 6))
    minv[:, :3, :3] = b.inv_mass[ids, None, None] * np.eye(3)
    if b.inv_inertia_world is not None:
        minv[:, 3:, 3:] = b.inv_inertia_world[ids]
    return J.reshape(3 * C, 6 * N), minv


def _least_norm(W: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with W x = rhs for a symmetric positive semi-definite W, of least norm: the
    Cholesky solve of (W + eps 1) x = rhs, eps = 1e-10 of the mean diagonal (the limit
    eps -> 0 is the least-norm solution; it leaves W x off by eps |x|, which the sweeps
    after it remove); a least-squares solve if that fails."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve  # here: scipy costs a process ~0.15 s to import, and only touching boxes need it

    eps = 1e-10 * max(float(np.trace(W)) / len(W), 1e-300)
    try:
        return cho_solve(cho_factor(W + eps * np.eye(len(W)), check_finite=False), rhs, check_finite=False)
    except LinAlgError:
        return np.linalg.lstsq(W, rhs, rcond=1e-10)[0]


def _direct_solve(W: np.ndarray, u0: np.ndarray, target: np.ndarray, mu: np.ndarray, lam: np.ndarray) -> None:
    """The impulses (in place in `lam`) that meet every contact's targets exactly, sticking:
    W lambda = (target, 0, 0 per contact) - u0, least norm (a face's 4 coplanar points
    are redundant: W is singular), without the contacts that would pull (at
    most 4 rounds of dropping them), friction then clamped to the kinetic cone. The start of
    the iteration when the warm start is off (a stack's first steps): Gauss-Seidel alone
    carries a stack's weight down only one level per sweep, and converges slowly on the
    redundant rows of a resting face."""
    C = target.size
    rhs = -u0.copy()
    rhs[0::3] += target
    active = np.ones(C, bool)
    out = np.zeros(3 * C)
    for _ in range(4):
        rows = np.flatnonzero(np.repeat(active, 3))
        out[:] = 0.0
        if rows.size == 0:
            break
        out[rows] = _least_norm(W[np.ix_(rows, rows)], rhs[rows])
        pulls = active & (out[0::3] < 0)
        if not pulls.any():
            break
        active &= ~pulls
    ln = np.maximum(out[0::3], 0.0)
    lt = out.reshape(C, 3)[:, 1:]
    size = np.linalg.norm(lt, axis=1)
    scale = np.minimum(1.0, mu * ln / np.where(size > 0, size, 1.0))
    lam[0::3] = ln
    lam.reshape(C, 3)[:, 1:] = lt * scale[:, None]


def _pgs(W: np.ndarray, u0: np.ndarray, target: np.ndarray, mu: np.ndarray, mu_s: np.ndarray, lam: np.ndarray, order: np.ndarray, sweeps: int,
         tol: float) -> bool:
    """Projected Gauss-Seidel on the accumulated impulses `lam` [3C] (in place): normal rows
    clamped to push, friction pairs to the Coulomb disk (static mu_s, else kinetic mu).
    Returns whether a sweep changed no contact velocity by more than `tol` (m/s) within
    `sweeps` sweeps."""
    diag = np.diag(W).copy()
    inv_d = 1.0 / np.where(diag > 1e-300, diag, 1.0)
    for _ in range(sweeps):
        before = lam.copy()
        for c in order.tolist():
            k = 3 * c
            u = u0[k:k + 3] + W[k:k + 3] @ lam
            ln = max(0.0, lam[k] + (target[c] - u[0]) * inv_d[k])
            dn = ln - lam[k]
            lam[k] = ln
            t1 = lam[k + 1] - (u[1] + W[k + 1, k] * dn) * inv_d[k + 1]
            t2 = lam[k + 2] - (u[2] + W[k + 2, k] * dn) * inv_d[k + 2]
            norm = (t1 * t1 + t2 * t2) ** 0.5
            cap = norm if norm <= mu_s[c] * ln else mu[c] * ln
            scale = cap / norm if norm > 0 else 0.0
            lam[k + 1], lam[k + 2] = t1 * scale, t2 * scale
        if np.abs(W @ (lam - before)).max() <= tol:
            return True
    return False


def _store(shapes: ShapeSet, f: Flat, lam: np.ndarray) -> None:
    """Keep this step's impulses for the next step's warm start."""
    static = f.a < 0
    shapes.keys.append(f.key[static])
    shapes.lams.append(lam[static])
    pair = np.flatnonzero(~static)
    if pair.size == 0:
        return
    codes = f.a[pair] * (int(f.b.max()) + 1) + f.b[pair]
    for code in np.unique(codes).tolist():
        sel = pair[codes == code]
        shapes.pair_next[(int(f.a[sel[0]]), int(f.b[sel[0]]))] = (f.local_b[sel], lam[sel])


def _sleep(b: ContactBodies, shapes: ShapeSet, q1: np.ndarray, ids: np.ndarray, la: np.ndarray, lb: np.ndarray, h: float) -> None:
    """Sleeping, as Box2D's and Bullet's islands: a body slower than SLEEP_SPEED (and turning
    slower than SLEEP_SPEED / SLEEP_RADIUS) is calm; when every body of a connected set of
    touching boxes has been calm for SLEEP_TIME, the set sleeps: each body is held at the
    pose where it fell asleep, at rest (v = w = 0). Anything that speeds one of them up
    (a hit, a push, a support taken away) wakes the set. It stops the slow lean that
    rounding starts in a tall stack whose contacts are re-solved every step."""
    w = b.w1[ids] if b.w1 is not None else np.zeros((ids.size, 3))
    calm = (np.linalg.norm(b.v1[ids], axis=1) < SLEEP_SPEED) & (np.linalg.norm(w, axis=1) < SLEEP_SPEED / SLEEP_RADIUS)
    clock = np.where(calm, shapes.calm[ids] + h, 0.0)
    shapes.calm[ids] = clock
    from scipy.sparse import coo_matrix  # here, as in _least_norm
    from scipy.sparse.csgraph import connected_components

    pair = la >= 0
    graph = coo_matrix((np.ones(int(pair.sum())), (la[pair], lb[pair])), shape=(ids.size, ids.size))
    _, label = connected_components(graph, directed=False)
    low = np.full(label.max() + 1, np.inf)
    np.minimum.at(low, label, clock)
    asleep = low[label] >= SLEEP_TIME
    falls = asleep & ~shapes.sleeping[ids]  # no rest pose kept yet for these
    shapes.sleeping[ids] = asleep
    if falls.any():
        shapes.rest_x[ids[falls]] = b.x1[ids[falls]]
        shapes.rest_q[ids[falls]] = q1[ids[falls]]
    held = ids[asleep]
    b.x1[held] = shapes.rest_x[held]
    q1[held] = shapes.rest_q[held]
    b.v1[held] = 0.0
    if b.w1 is not None:
        b.w1[held] = 0.0


def _lift(b: ContactBodies, f: Flat, q1: np.ndarray, ids: np.ndarray, la: np.ndarray, lb: np.ndarray, order: np.ndarray, up: np.ndarray) -> None:
    """The position pass: contacts bottom up, each separation brought back to >= 0 by moving
    the upper body along n (shock propagation; two level bodies share by inverse mass)."""
    rot = quat_to_matrix(quat_normalize(q1[ids]))
    pb = b.x1[f.b] + np.einsum("cij,cj->ci", rot[lb], f.local_b)
    pa = np.where((f.a >= 0)[:, None], b.x1[np.maximum(f.a, 0)] + np.einsum("cij,cj->ci", rot[np.maximum(la, 0)], f.local_a), f.local_a)
    sep = np.einsum("ij,ij->i", pb - pa, f.normal)
    rise = f.normal @ up
    w = b.inv_mass[ids]
    dx = np.zeros((ids.size, 3))
    for c in order.tolist():
        i, j = int(la[c]), int(lb[c])
        n = f.normal[c]
        gap = sep[c] + n @ (dx[j] - (dx[i] if i >= 0 else 0.0))
        if gap >= 0:
            continue
        if i < 0 or w[i] == 0 or (rise[c] > 0.5 and w[j] > 0):
            share_b = 1.0 if w[j] > 0 else 0.0
        elif w[j] == 0 or rise[c] < -0.5:
            share_b = 0.0
        else:
            share_b = w[j] / (w[i] + w[j])
        dx[j] -= share_b * gap * n
        if i >= 0:
            dx[i] += (1.0 - share_b) * gap * n
    b.x1[ids] += dx
