"""The broadphase over everything that moves: one ellipsoid per moving thing, holding it
across the whole shutter, in ONE Mitsuba scene whose BVH (the engine's own) is rebuilt
per frame from one buffer.

Mitsuba's `ellipsoids` shape reports a ray's *entry* into an ellipsoid only (a ray that
starts inside one does not see it). The kernel (render/kernel/world.py) walks a ray's entries in
order, each a candidate for the exact test at the ray's own time, starting the walk a
distance `reach` behind the ray's origin: every proxy is smaller across than `reach`, so
each one that the ray's segment meets is entered after that start, and none is missed
(docs/rendering.md, "One traversal for everything that moves").

The shutter is cut into parts (`parts`: up to `PARTS`, each one or more segments between
baked samples), and each moving thing has one proxy per part, holding it over that part
only; part b's proxies sit in a region of their own, moved by b `spacing` along x, and a
lane walks the region of its own time's part. A fast thing's proxy is then a fraction of
its streak, and a ray walks fewer of them, with the same trace sites.

Proxies, computed here on the host from the baked samples across the shutter:
- a rigid mover: its swept sphere (render/poses/kernel.py `swept_spheres`);
- a particle: the capsule its sphere sweeps along its path (the chord from the first to
  the last sample, thickened by the farthest sample from that chord), held by a sphere
  when the path is short, else by an ellipsoid along the chord (semi-axes sqrt(2) (h + r)
  and sqrt(2) r hold a capsule of half-length h and radius r); a particle dead at every
  sample has an empty proxy far away.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ...motion.pose import quat_rotate

FLOATS = 10  # one ellipsoid in Mitsuba's data buffer: centre (3), semi-axes (3), quaternion (x, y, z, w)
FAR = 1e9  # where empty proxies sit: no ray reaches them within a scene's reach


def swept_spheres(t: np.ndarray, q: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Each mover's world-space sphere [M, 4] (centre, radius) that holds it at every time
    of the shutter, from its N baked samples t [M, N, 3], q [M, N, 4] and its rest-frame
    bounding sphere rest [M, 4] (`bounding_spheres`).

    Between samples j and j + 1 the rest centre c lies at lerp(t) + slerp(q) c: inside the
    parallelogram of the four points t_a + R(q_b) c (a, b in {j, j + 1}), but for the arc
    that the rotation bows out of its chord, by at most |c| (1 - cos(theta / 2)) =
    |c| (1 - |q_j . q_j+1|). The sphere holds all those corners, that bow and the rest
    radius, padded for float32 rounding in the kernel (positions far from the origin round
    to about 6e-8 of their distance)."""
    m = len(rest)
    out = np.zeros((m, 4))
    if m == 0:
        return out
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    c = np.broadcast_to(np.asarray(rest, dtype=float)[:, None, :3], t.shape)
    rc = quat_rotate(q, c)
    corners = np.concatenate([t + rc, t[:, :-1] + rc[:, 1:], t[:, 1:] + rc[:, :-1]], axis=1)
    centre = (corners.min(axis=1) + corners.max(axis=1)) / 2
    reach = np.sqrt(((corners - centre[:, None]) ** 2).sum(axis=2)).max(axis=1)
    dots = np.abs((q[:, :-1] * q[:, 1:]).sum(axis=2)) if q.shape[1] > 1 else np.ones((m, 1))
    bow = np.linalg.norm(rest[:, :3], axis=1) * (1.0 - np.minimum(dots, 1.0)).max(axis=1)
    radius = reach + bow + rest[:, 3]
    out[:, :3] = centre
    out[:, 3] = radius * (1 + 1e-4) + 1e-6 * np.abs(centre).max(axis=1) + 1e-5
    return out


def sphere_proxies(spheres: np.ndarray) -> np.ndarray:
    """Ellipsoid records [P, 10] for spheres [P, 4] (centre, radius)."""
    out = np.zeros((len(spheres), FLOATS))
    out[:, :3] = spheres[:, :3]
    out[:, 3:6] = spheres[:, 3:4]
    out[:, 9] = 1.0
    return out


def particle_proxies(positions: np.ndarray, alive: np.ndarray, radius: np.ndarray, also: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Ellipsoid records [C, 10] holding each particle across the shutter: positions
    [C, N, 3] and alive [C, N] at the N samples in time order, radius [C]; `also`:
    (positions [C, 3], alive [C]) at one more instant inside the shutter (the frame's
    time), held too. The chord runs from the first to the last live sample in time: with
    the frame's time (the shutter's middle, for a centred shutter) taken as an end, the
    chord covered half the path and the proxies grew to spheres of the path's length
    (cannonball-splash's spray: 2.3x across).

    Computed a coordinate (and a record's field) at a time, as rows [3, C] and [10, C]
    turned into records at the end: numpy walks a whole column faster than it reduces
    each row of 2 to 4 values. The farthest sample from the chord is searched among the
    samples between its ends only (an end lies on the chord, a sample outside them is
    dead), so a part of two samples has none (100,000 particles, 8 parts: 0.58 s -> 0.09 s)."""
    count = len(positions)
    if count == 0:
        return np.zeros((0, FLOATS))
    n = alive.shape[1]
    # the path's ends: the first and last samples the particle is alive at, sample 0 and
    # n - 1 but for the few born or dying during the shutter (and where it is alive at
    # none: its proxy is replaced below)
    positions = np.asarray(positions, dtype=float)
    at = np.ascontiguousarray(np.asarray(alive).T, dtype=bool)  # [N, C]: a row of alive at a time
    in_shutter = at.any(axis=0)
    a = _pick(positions, in_shutter & ~at[0], lambda some: np.argmax(at[:, some], axis=0), 0)
    b = _pick(positions, in_shutter & ~at[n - 1], lambda some: n - 1 - np.argmax(at[::-1, some], axis=0), n - 1)
    live = in_shutter
    if also is not None:  # the `also` instant is both ends where no sample is live
        also_p, also_a = np.asarray(also[0], dtype=float), np.asarray(also[1], dtype=bool)
        np.copyto(a, also_p.T, where=~in_shutter)
        np.copyto(b, also_p.T, where=~in_shutter)
        live = in_shutter | also_a
    chord = b - a
    length = np.sqrt((chord[0] * chord[0] + chord[1] * chord[1]) + chord[2] * chord[2])
    # the chord's unit axis; 0 for a path of no length (no turn, as +X; nothing to project on)
    axis = chord / np.where(length > 0, length, 1.0)
    # the farthest live sample from the chord segment (a path that bends: gravity): the
    # samples strictly between the ends, and the `also` instant where it is not an end
    dev = np.zeros(count)
    if n > 2:
        _farthest(positions[:, 1:n - 1], at[1:n - 1], a, axis, length, dev)
    if also is not None:
        _farthest(also_p[:, None], also_a[None], a, axis, length, dev)
    r = np.asarray(radius, dtype=float) + dev
    h = length / 2
    rows = np.empty((FLOATS, count))  # the records' fields, turned into records at the end
    centre = rows[:3]
    np.add(a, b, out=centre)
    centre /= 2
    # float32 rounding in the kernel (positions far from the origin round to ~6e-8 of their distance)
    pad = 1e-4 * (h + r) + 1e-6 * _largest(np.abs(centre)) + 1e-6
    sphere = h < 0.68 * r  # a short path: a sphere of radius h + r is the smaller proxy
    hr = h + r
    np.add(np.where(sphere, hr, np.sqrt(2.0) * hr), pad, out=rows[3])
    np.add(np.where(sphere, hr, np.sqrt(2.0) * r), pad, out=rows[4])
    rows[5] = rows[4]
    _quat_from_x(axis, rows[6:10])
    dead = ~live
    if dead.any():  # an empty proxy far away (turned as for a path of no length)
        rows[:, dead] = np.array([FAR, FAR, FAR, 1e-6, 1e-6, 1e-6, 0.0, 0.0, 0.0, 1.0])[:, None]
    return np.ascontiguousarray(rows.T)


def _pick(positions: np.ndarray, other: np.ndarray, index: Callable[[np.ndarray], np.ndarray], usual: int) -> np.ndarray:
    """One sample of each particle from positions [C, N, 3], as rows [3, C]: sample
    `usual`, but for the particles `other` [C] (a mask), whose sample `index` gives from
    their indices (a fancy index over every particle cost as much as the rest of a part's
    proxies)."""
    out = np.array(positions[:, usual].T, order="C")
    some = np.flatnonzero(other)
    if len(some):
        out[:, some] = positions[some, index(some)].T
    return out


def _farthest(points: np.ndarray, alive: np.ndarray, a: np.ndarray, axis: np.ndarray, length: np.ndarray, dev: np.ndarray) -> None:
    """dev [C] raised to the distance of each live point [C, K, 3] (alive: rows [K, C])
    from its chord: the segment from a along the unit axis (rows [3, C]) for length [C].
    Computed on rows [3, K, C] (numpy walks rows of C values fast, [..., 3] slowly)."""
    rel = np.empty((3,) + points.shape[1::-1])
    for k in range(3):
        np.subtract(points[:, :, k].T, a[k], out=rel[k])
    s = rel[0] * axis[0]
    s += rel[1] * axis[1]
    s += rel[2] * axis[2]
    np.clip(s, 0.0, length, out=s)  # the nearest point of the chord, as a distance along it
    off = np.zeros_like(s)  # the square of the distance to it
    for k in range(3):
        rel[k] -= s * axis[k]
        rel[k] *= rel[k]
        off += rel[k]
    off = np.where(alive, off, 0.0)  # a dead sample may lie anywhere
    np.maximum(dev, np.sqrt(off.max(axis=0)), out=dev)  # the root of the largest square: the largest root


def _quat_from_x(axis: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Unit quaternions (x, y, z, w), as rows [4, C] (into `out` where given), turning +X
    onto each unit axis, rows [3, C] (no turn for a zero axis): the half-way rotation
    (+X cross axis, 1 + +X . axis) = (0, -z, y, 1 + x), normalised."""
    q = np.empty((4, axis.shape[1])) if out is None else out
    q[0] = 0.0
    np.negative(axis[2], out=q[1])
    q[2] = axis[1]
    np.add(1.0, axis[0], out=q[3])
    opposite = axis[0] < -1.0 + 1e-12  # half a turn: about +Z
    if opposite.any():
        q[:, opposite] = np.array([0.0, 0.0, 1.0, 0.0])[:, None]
    q[1:] /= np.sqrt((q[1] * q[1] + q[2] * q[2]) + q[3] * q[3])
    return q


PARTS = 8  # at most this many parts of the shutter, each with its own proxies


def parts(n: int) -> list[tuple[int, int]]:
    """The baked samples (first, last, both held) of each part of a shutter sampled at n
    instants: B = min(PARTS, n - 1) equal parts of the shutter fraction, part b holding
    u in [b / B, (b + 1) / B], so every sample a lane in it interpolates between."""
    count = max(1, min(PARTS, n - 1))
    out = []
    for b in range(count):
        x0, x1 = b * (n - 1) / count, (b + 1) * (n - 1) / count
        out.append((int(np.floor(x0 + 1e-9)), min(int(np.ceil(x1 - 1e-9)), n - 1)))
    return out


def far_proxies(count: int) -> np.ndarray:
    """`count` empty proxy records far away: out of every ray's reach (`FAR`)."""
    out = np.zeros((count, FLOATS))
    out[:, :3], out[:, 3:6], out[:, 9] = FAR, 1e-6, 1.0
    return out


def worth_parts(whole: np.ndarray, per_part: list[np.ndarray]) -> bool:
    """Whether proxies per part of the shutter would be met by rays less often than the
    proxies over the whole shutter: their mean cross-section (semi-axes long x side,
    summed over the live proxies) at most half the whole's. Slow things gain nothing from
    parts, and a broadphase of B times the proxies costs each trace a few BVH levels more
    (4 slow movers at the preview preset: 5% of the frame)."""
    def area(records: np.ndarray) -> float:
        live = records[np.abs(records[:, 0]) < FAR / 2]
        return float((live[:, 3] * live[:, 4]).sum())

    return bool(per_part) and float(np.mean([area(p) for p in per_part])) <= 0.5 * area(whole)


def in_regions(per_part: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
    """Each part's proxies [P, 10] in its own region: part b moved by b * spacing along x,
    the spacing more than the box holding every live proxy is wide, so no two regions
    meet. (all records [B * P, 10], part-major; the box [2, 3] in world space; the spacing)."""
    lives = [_live(p) for p in per_part]
    boxes = [_box(p, live) for p, live in zip(per_part, lives)]
    live_boxes = [b for b in boxes if np.abs(b[0, 0]) < FAR / 2]
    box = np.stack([np.min([b[0] for b in live_boxes], axis=0), np.max([b[1] for b in live_boxes], axis=0)]) if live_boxes else EMPTY_BOX.copy()
    spacing = 1.25 * float(box[1, 0] - box[0, 0]) + 1e-3 if live_boxes else 0.0
    out = np.concatenate(per_part) if per_part else np.zeros((0, FLOATS))
    at = 0
    for b, (part, live) in enumerate(zip(per_part, lives)):
        records = out[at:at + len(part)]
        at += len(part)
        if b == 0 or spacing == 0.0:
            continue
        shift = b * spacing  # live proxies only: empty ones stay far away
        np.add(records[:, 0], shift, out=records[:, 0], where=live)
        for k in range(3, 6):  # padded for float32 at the moved position (rounds coarser far from the origin)
            np.add(records[:, k], 1e-6 * shift, out=records[:, k], where=live)
    return out, box, spacing


def separate(proxies: np.ndarray, scale: float) -> np.ndarray:
    """The proxies [P, 10] with coincident ones made apart: proxies whose centres lie
    within a few float steps of each other (the parts of one rigid body share one swept
    sphere; particles emitted from one point) are entered at the same distance, and the
    walk, which steps past each entry it visits, would skip all but one. Within each such
    group the semi-axes grow by a gap per rank, so their entries along any ray differ by
    more than the walk's step. `scale`: a bound on the walk's distances and the probes'
    coordinates (its step is about 2e-7 of the one, 2.4e-7 of the other).

    The groups are the proxies sharing a cell (`_cells`), ranked by the long semi-axis,
    then by index. Only proxies that share a hash of their cell with another can share a
    cell, and only those are sorted by cell: a lexsort of every proxy over four keys cost
    0.038 s a part at 100,000 particles (now 0.009 s)."""
    out = np.array(proxies, dtype=float, copy=True)
    if len(out) < 2:
        return out
    gap = 4.0 * (4e-7 * scale + 2e-7)  # more than the walk's step at any of its distances
    # live proxies only: an empty one lies far away, out of every walk's reach (grown by
    # rank as one group, a spray's 35,000 dead particles made 100 m proxies out there, one
    # cluster of overlapping records for the BVH build)
    live = np.flatnonzero(np.abs(out[:, 0]) < FAR / 2)
    if len(live) < 2:
        return out
    cells = _cells(out[live])
    # a hash of each cell (wrapping products: any collision only adds proxies to the sort)
    u = cells.view(np.uint64)
    key = u[0] * np.uint64(0x9E3779B97F4A7C15)
    key += u[1] * np.uint64(0xC2B2AE3D27D4EB4F)
    key += u[2] * np.uint64(0x165667B19E3779F9)
    order = np.argsort(key)
    repeat = key[order[1:]] == key[order[:-1]]
    if not repeat.any():
        return out
    shared = np.zeros(len(live), dtype=bool)
    shared[order[1:][repeat]] = True
    shared[order[:-1][repeat]] = True
    some = np.flatnonzero(shared)  # in index order: ties stay in it (lexsort is stable)
    order = some[np.lexsort((out[live[some], 3], cells[2, some], cells[1, some], cells[0, some]))]
    c = cells[:, order]
    same = np.concatenate([[False], np.all(c[:, 1:] == c[:, :-1], axis=0)])
    if not same.any():
        return out
    # rank within each run of one cell: 0, 1, 2, ... (runs start where `same` is False)
    start = np.maximum.accumulate(np.where(~same, np.arange(len(order)), 0))
    rank = np.arange(len(order)) - start
    grown = rank > 0  # the first of each run keeps its semi-axes
    out[live[order[grown]], 3:6] += (rank[grown] * gap)[:, None]
    return out


def _cells(proxies: np.ndarray) -> np.ndarray:
    """Each proxy's cell for `separate`, as rows [3, P] (int64): coincident means centres
    within a few float32 steps of their own size (not of the walk's scale: a spray's
    particles a centimetre apart are distinct, and grouped by the walk's scale a 20 km sea
    plane made one group of a whole spray and grew its proxies by metres)."""
    centres = proxies[:, :3].T.copy()
    size_of = np.abs(centres)
    live = size_of[0] < FAR / 2
    size = float(np.where(live, _largest(size_of), 0.0).max()) if live.any() else 1.0
    near = 4e-7 * size + 2e-7
    centres /= 8.0 * near
    return np.floor(centres, out=centres).astype(np.int64)


EMPTY_BOX = np.full((2, 3), FAR)  # a point far away: no ray within a scene's reach meets it


def union_box(proxies: np.ndarray) -> np.ndarray:
    """The box [2, 3] (min, max) holding every live proxy (each ellipsoid's centre plus or
    minus its largest semi-axis), padded for float32; `EMPTY_BOX` when none is live. A ray
    segment that misses it meets no proxy, and the kernel skips its walk."""
    return _box(proxies, _live(proxies))


def _box(proxies: np.ndarray, live: np.ndarray) -> np.ndarray:
    """`union_box` of the proxies [P, 10] whose mask `live` [P] is set (reduced as rows
    [6, L] of the live ones' fields: numpy reduces [P, 3] along its short axis slowly)."""
    if not live.any():
        return EMPTY_BOX.copy()
    rows = proxies[live, :6].T.copy()
    half = _largest(rows[3:6])
    lo = (rows[:3] - half).min(axis=1)
    hi = (rows[:3] + half).max(axis=1)
    pad = 1e-4 * float((hi - lo).max()) + 1e-6 * float(np.abs(np.concatenate([lo, hi])).max()) + 1e-6
    return np.stack([lo - pad, hi + pad])


def reach(proxies: np.ndarray) -> float:
    """How far behind a ray's origin its broadphase walk starts: more than any live proxy
    is across (twice its largest semi-axis), padded."""
    live = _live(proxies)
    if not live.any():
        return 1e-3
    return float(2.0 * np.where(live, _largest(proxies[:, 3:6].T), -np.inf).max() * (1 + 1e-3) + 1e-3)


def _largest(rows: np.ndarray) -> np.ndarray:
    """The largest of three rows [3, P] in each column [P]: a proxy's largest semi-axis,
    or its centre's largest coordinate (numpy reduces [P, 3] along its short axis slowly)."""
    return np.maximum(np.maximum(rows[0], rows[1]), rows[2])


def _live(proxies: np.ndarray) -> np.ndarray:
    """Which proxies [P, 10] are live (not far away: `FAR`), as a mask [P]."""
    return np.abs(proxies[:, 0]) < FAR / 2 if len(proxies) else np.zeros(0, dtype=bool)


class Broadphase:
    """The ellipsoids scene of one job, with room for `capacity` proxies (a larger count
    rebuilds it: one new kernel). `make_scene`: the SBT owner's scene builder."""

    def __init__(self, mi: Any, make_scene: Callable[[dict[str, Any]], Any]) -> None:
        self._mi = mi
        self._make_scene = make_scene
        self.scene: Any = None
        self._params: Any = None
        self.count = 0

    def update(self, proxies: np.ndarray) -> None:
        """The frame's proxies [P, 10]: one buffer written, one BVH build."""
        mi = self._mi
        data = np.asarray(proxies, dtype=np.float32)
        fresh = self.scene is None or len(data) != self.count
        if fresh:
            tensor = lambda a: mi.TensorXf(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
            shape = {"type": "ellipsoids", "extent": 1.0, "centers": tensor(data[:, :3]), "scales": tensor(data[:, 3:6]), "quaternions": tensor(data[:, 6:10])}
            self.scene = self._make_scene({"type": "scene", "broadphase": shape})
            self._params = mi.traverse(self.scene)
            self.count = len(data)
        # written through the parameter update on every frame, the first too: a frame then
        # traces the same variables, in the same order, as the next, and the cold frame's
        # kernels are the warm frames' (a fresh shape's own arrays would compile them again)
        import drjit as dr

        # written in place (no new variable each frame): with a new buffer per frame the
        # render's kernels came in two variants, one or the other per frame. The write is
        # in place, or a copy where something still holds the buffer (timing decides); a new
        # scene is written both ways, so both kernels are the cold frame's to compile.
        for shared in ([True, False] if fresh else [False]):
            current = self._params["broadphase.data"]
            held = mi.Float(current) if shared else None  # a second reference: the copying write
            dr.scatter(current, mi.Float(data.ravel()), dr.arange(mi.UInt32, data.size))
            self._params.set_dirty("broadphase.data")
            self._params.update()
            dr.eval()
            del held
        # the BVH built and every value of the update evaluated here, the same way each
        # frame: one ray traced now (a trace waits for the build). Left to the render's first
        # trace, the build's own kernels ran inside it on some frames and not on others, and
        # the render's kernels came in two variants

        probe = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(0.0, 0.0, 1.0))
        dr.eval(self.scene.ray_intersect_preliminary(probe).t)
        dr.sync_thread()
