"""Motion planning: a `plan` motion source (docs/seed-motion.md, "Motion planning").

Stages, once per planned object (cached by scene, object and block):
  grid      -> occupancy on the floor plane (world X across, Z along the rows, +Y up), from
               an image or from the scene's static objects in a height band; outside = wall
  inflate   -> cells whose centre is closer than need = radius + tolerance + margin to a
               wall square are blocked (exact square distance, scipy binary dilation)
  search    -> A* per leg (start, waypoints, goal), 8-connected, step cost = length, octile
               heuristic (admissible and consistent), no diagonal past a blocked corner
  shorten   -> greedy line of sight: from each kept vertex, the farthest later vertex whose
               straight segment keeps `need` from every wall
  smooth    -> centripetal Catmull-Rom through the kept vertices (heights linear along each
               leg); densely sampled, every sample must keep radius + tolerance (a Lipschitz
               bound between samples); a segment that does not gets its chord's midpoint
               as a new vertex, until all do
  profile   -> trapezoidal speed profile over the arc length (accelerate, cruise, brake)
  pose      -> position p(s(t)); facing along the tangent, banking by the lateral
               acceleration (roll = atan(a_lat / g)) when asked
The follower (a simulated vehicle tracking this reference) runs in the dynamics stage
(dynamics/follower.py); `follower_pose` here poses the object it carries.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from functools import cached_property
import pathlib
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.ndimage import binary_dilation
from scipy.spatial.transform import Rotation

from ..errors import GridTooLargeError, SceneError
from ..geometry import shape_geometry
from .pose import Pose, quat_mul
from .rotation import parent_from_object, transform_quat

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene

MAX_CELLS = 4_000_000  # cells a grid may have (memory and search time are bounded by it)
UP = np.array([0.0, 1.0, 0.0])
SQRT2 = math.sqrt(2.0)


def _xyz(p: Sequence[float]) -> str:
    return "(" + ", ".join(f"{float(c):g}" for c in p) + ")"


class _Located(Exception):
    """A planning failure at a path inside the motion block (turned into a SceneError)."""

    def __init__(self, loc: tuple[Any, ...], message: str) -> None:
        super().__init__(message)
        self.loc = loc


# --- the grid -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Grid:
    """wall [rows (z), cols (x)] bool; `cell` metres; `origin` the world (x, z) of the
    corner of cell (0, 0)."""

    wall: np.ndarray
    cell: float
    origin: np.ndarray

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """World (x, z) of cell centres."""
        return np.stack((self.origin[0] + (cols + 0.5) * self.cell, self.origin[1] + (rows + 0.5) * self.cell), axis=-1)

    def cell_of(self, xz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of the cells holding points (x, z); may be outside the grid."""
        q = np.floor((np.asarray(xz) - self.origin) / self.cell).astype(np.int64)
        return q[..., 1], q[..., 0]

    def clearance(self, xz: np.ndarray, reach: float) -> np.ndarray:
        """Distance (m) from points (x, z) [P, 2] to the nearest wall square (outside the
        grid is wall), exact up to `reach`, and at least `reach` where it says so."""
        xz = np.atleast_2d(np.asarray(xz, dtype=np.float64))
        w = int(math.ceil(reach / self.cell)) + 1
        d = np.arange(-w, w + 1)
        di, dj = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
        rows_n, cols_n = self.wall.shape
        out = np.empty(len(xz))
        chunk = max(1, 2_000_000 // len(di))
        for a in range(0, len(xz), chunk):
            p = xz[a : a + chunk]
            r0, c0 = self.cell_of(p)
            r, c = r0[:, None] + di[None, :], c0[:, None] + dj[None, :]
            inside = (r >= 0) & (r < rows_n) & (c >= 0) & (c < cols_n)
            wall = ~inside
            wall[inside] = self.wall[r[inside], c[inside]]
            x_lo = self.origin[0] + c * self.cell
            z_lo = self.origin[1] + r * self.cell
            dx = np.maximum(np.maximum(x_lo - p[:, :1], p[:, :1] - (x_lo + self.cell)), 0.0)
            dz = np.maximum(np.maximum(z_lo - p[:, 1:], p[:, 1:] - (z_lo + self.cell)), 0.0)
            dist = np.where(wall, np.hypot(dx, dz), np.inf)
            out[a : a + chunk] = np.minimum(dist.min(axis=1), max(reach, (w - 1) * self.cell))
        return out

    def blocked(self, need: float) -> np.ndarray:
        """Cells whose centre is closer than `need` to a wall square (outside = wall)."""
        w = int(math.ceil(need / self.cell)) + 1
        d = np.arange(-w, w + 1)
        di, dj = np.meshgrid(d, d, indexing="ij")
        gap = self.cell * np.hypot(np.maximum(np.abs(di) - 0.5, 0.0), np.maximum(np.abs(dj) - 0.5, 0.0))
        kernel = gap < need
        padded = np.pad(self.wall, w, constant_values=True)
        return binary_dilation(padded, structure=kernel)[w:-w, w:-w] | self.wall


def grid_from_image(path: pathlib.Path, cell: float, origin: Sequence[float], threshold: float) -> Grid:
    """Walls where the image's luminance (0..1) is below `threshold`; one pixel per cell,
    row 0 at origin z, column 0 at origin x."""
    from PIL import Image

    with Image.open(path) as img:
        if img.width * img.height > MAX_CELLS:
            raise GridTooLargeError(f"{path.name}: {img.width} x {img.height} pixels is more than {MAX_CELLS} cells")
        grey = np.asarray(img.convert("L"), dtype=np.float64) / 255.0
    return Grid(grey < threshold, float(cell), np.asarray(origin, dtype=np.float64))


def _static_world(loaded: "LoadedScene", skip: str) -> list[tuple[Any, np.ndarray]]:
    """(object, world_from_object 4x4) of every object that does not move (through its
    parents), except `skip`."""
    objects = {o.name: o for o in loaded.scene.objects}
    out = []
    for obj in loaded.scene.objects:
        if obj.name == skip or obj.deform is not None:
            continue
        m, node, still = np.eye(4), obj, True
        while node is not None:
            if node.motion.type != "static":
                still = False
                break
            m = parent_from_object(node.transform) @ m
            node = objects.get(node.parent) if node.parent is not None else None
        if still:
            out.append((obj, m))
    return out


def grid_from_scene(loaded: "LoadedScene", skip: str, cell: float, origin: Sequence[float], size: Sequence[float], band: Sequence[float]) -> Grid:
    """Walls: cells where a static solid shape (geometry.py `inside`: cube, sphere,
    cylinder ...) or a mesh's bounding box reaches into the height band, tested
    at 3 x 3 points per cell and 5 heights."""
    from ..meshes import load_mesh

    cols, rows = int(math.ceil(size[0] / cell)), int(math.ceil(size[1] / cell))
    if rows * cols > MAX_CELLS:
        raise GridTooLargeError(f"a {size[0]} x {size[1]} m grid of {cell} m cells has {rows * cols} cells (limit {MAX_CELLS})")
    wall = np.zeros((rows, cols), dtype=bool)
    sub = (np.arange(3) + 0.5) / 3.0
    heights = np.linspace(band[0], band[1], 5)
    rr, cc = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    for obj, m in _static_world(loaded, skip):
        entry = shape_geometry(obj.shape)
        if entry.inside is None and not entry.file_mesh:
            continue  # not solid (a rectangle, a disk, an empty)
        inv = np.linalg.inv(m)
        if entry.file_mesh:
            verts = load_mesh(loaded.asset(obj.file))[0]
            lo, hi = verts.min(axis=0), verts.max(axis=0)
        for su in sub:
            for sv in sub:
                x = origin[0] + (cc + su) * cell
                z = origin[1] + (rr + sv) * cell
                for y in heights:
                    p = np.stack((x, np.full_like(x, y), z, np.ones_like(x)), axis=-1) @ inv.T
                    p = p[..., :3]
                    if entry.file_mesh:  # a mesh file: its bounding box
                        inside = np.all((p >= lo) & (p <= hi), axis=-1)
                    else:
                        inside = entry.inside(obj, p)  # type: ignore[misc]
                    wall |= inside
    return Grid(wall, float(cell), np.asarray(origin, dtype=np.float64))


# --- search -------------------------------------------------------------------------------


def astar(blocked: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> tuple[list[tuple[int, int]], float] | None:
    """Shortest 8-connected path (in cells; orthogonal steps cost 1, diagonal sqrt 2) from
    `start` to `goal` over cells not `blocked`; a diagonal step needs both cells beside it
    free. Returns (cells, cost) or None. Heuristic: octile distance, admissible and
    consistent, so the first time the goal is popped its cost is optimal."""
    rows, cols = blocked.shape
    if blocked[start] or blocked[goal]:
        return None
    gr, gc = goal

    def h(r: int, c: int) -> float:
        dr, dc = abs(r - gr), abs(c - gc)
        return (SQRT2 - 1.0) * min(dr, dc) + max(dr, dc)

    g = np.full(rows * cols, np.inf)
    parent = np.full(rows * cols, -1, dtype=np.int64)
    closed = np.zeros(rows * cols, dtype=bool)
    s = start[0] * cols + start[1]
    g[s] = 0.0
    heap = [(h(*start), 0.0, s)]
    steps = ((-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0), (-1, -1, SQRT2), (-1, 1, SQRT2), (1, -1, SQRT2), (1, 1, SQRT2))
    goal_i = gr * cols + gc
    while heap:
        _, cost, i = heapq.heappop(heap)
        if closed[i]:
            continue
        closed[i] = True
        if i == goal_i:
            path = [i]
            while parent[path[-1]] >= 0:
                path.append(int(parent[path[-1]]))
            return [(p // cols, p % cols) for p in reversed(path)], float(cost)
        r, c = divmod(i, cols)
        for dr, dc, step in steps:
            nr, nc = r + dr, c + dc
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols or blocked[nr, nc]:
                continue
            if dr and dc and (blocked[r, nc] or blocked[nr, c]):
                continue  # no corner cutting
            j = nr * cols + nc
            new = cost + step
            if new < g[j]:
                g[j] = new
                parent[j] = i
                heapq.heappush(heap, (new + h(nr, nc), new, j))
    return None


def segment_clear(grid: Grid, a: np.ndarray, b: np.ndarray, need: float) -> bool:
    """True if every point of the segment a-b (x, z) is at least `need` from every wall:
    samples every h = cell / 4 keep need + h / 2 (distance is 1-Lipschitz)."""
    h = grid.cell / 4.0
    n = max(2, int(math.ceil(np.linalg.norm(b - a) / h)) + 1)
    s = np.linspace(0.0, 1.0, n)[:, None]
    spacing = np.linalg.norm(b - a) / (n - 1)
    return bool(np.all(grid.clearance(a + s * (b - a), need + spacing) >= need + spacing / 2))


def shorten(grid: Grid, points: np.ndarray, need: float) -> np.ndarray:
    """Greedy line of sight: keep the first point, then the farthest point visible from
    the last kept one (adjacent points are always kept as a fallback)."""
    kept = [0]
    i = 0
    n = len(points)
    while i < n - 1:
        j = i + 1
        # the farthest visible: scan forward while the straight segment stays clear
        lo = j
        step = 1
        while lo + step < n and segment_clear(grid, points[i], points[lo + step], need):
            lo += step
            step *= 2
        hi = min(n - 1, lo + step)
        while hi - lo > 1:  # bisect between the last clear and the first blocked probe
            mid = (lo + hi) // 2
            if segment_clear(grid, points[i], points[mid], need):
                lo = mid
            else:
                hi = mid
        if hi == n - 1 and hi != lo and segment_clear(grid, points[i], points[hi], need):
            lo = hi
        kept.append(lo)
        i = lo
    return points[kept]


# --- the spline ---------------------------------------------------------------------------


def catmull_rom(points: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Centripetal Catmull-Rom (alpha = 1/2, Barry-Goldman) through `points` [n, 3] at
    global parameters u in [0, n - 1] (segment k is u in [k, k + 1]); the ends continue
    straight (phantom points reflected)."""
    n = len(points)
    if n == 1:
        return np.broadcast_to(points[0], (len(u), 3)).copy()
    ext = np.concatenate((2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]))
    k = np.clip(np.floor(u).astype(np.int64), 0, n - 2)
    s = (u - k)[:, None]
    p0, p1, p2, p3 = ext[k], ext[k + 1], ext[k + 2], ext[k + 3]

    def knot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.maximum(np.linalg.norm(b - a, axis=1), 1e-9) ** 0.5

    t1 = knot(p0, p1)[:, None]
    t2 = t1 + knot(p1, p2)[:, None]
    t3 = t2 + knot(p2, p3)[:, None]
    t = t1 + s * (t2 - t1)
    a1 = (t1 - t) / t1 * p0 + t / t1 * p1
    a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2
    a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3
    b1 = (t2 - t) / t2 * a1 + t / t2 * a2
    b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3
    return (t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2


@dataclass(frozen=True)
class PlannedPath:
    """A planned root-motion path: spline vertices [n, 3], the arc-length table
    (u [K], s [K]), the A* legs' cells and costs, and the speed profile."""

    vertices: np.ndarray
    table_u: np.ndarray
    table_s: np.ndarray
    table_duds: np.ndarray
    cells: list[list[tuple[int, int]]]
    costs: list[float]
    speed: float
    accel: float
    decel: float
    start_time: float
    facing: str
    grid: Grid
    need: float  # clearance the spline keeps (radius + tolerance)

    @property
    def length(self) -> float:
        """Arc length of the smoothed path (m)."""
        return float(self.table_s[-1])

    def profile(self) -> tuple[float, float, float, float]:
        """(peak speed, accelerate, cruise, brake durations) of the trapezoid."""
        length, a, b, v = self.length, self.accel, self.decel, self.speed
        if v * v / (2 * a) + v * v / (2 * b) > length:  # no room to reach the cruise speed
            v = math.sqrt(2.0 * length * a * b / (a + b))
        t_a, t_b = v / a, v / b
        t_c = max(0.0, (length - v * v / (2 * a) - v * v / (2 * b)) / v) if v > 0 else 0.0
        return v, t_a, t_c, t_b

    @property
    def duration(self) -> float:
        """Seconds from the start to the stop (accelerate + cruise + brake)."""
        _, t_a, t_c, t_b = self.profile()
        return t_a + t_c + t_b

    def arc(self, t: np.ndarray) -> np.ndarray:
        """Distance travelled s(t) (m) along the path at times t (s)."""
        v, t_a, t_c, t_b = self.profile()
        a, b = self.accel, self.decel
        tau = np.clip(np.asarray(t, dtype=np.float64) - self.start_time, 0.0, t_a + t_c + t_b)
        s_a = 0.5 * a * np.minimum(tau, t_a) ** 2
        s_c = v * np.clip(tau - t_a, 0.0, t_c)
        tb = np.clip(tau - t_a - t_c, 0.0, t_b)
        s_b = v * tb - 0.5 * b * tb * tb
        return np.minimum(s_a + s_c + s_b, self.length)

    @cached_property
    def _u_of_s(self) -> CubicHermiteSpline:
        # cubic Hermite inverse of the arc-length table with the exact slopes du/ds: the
        # speed along the path matches the profile between samples, and keeps the jump of
        # dp/du at the vertices
        keep = np.concatenate(([True], np.diff(self.table_s) > 0))
        return CubicHermiteSpline(self.table_s[keep], self.table_u[keep], self.table_duds[keep])

    def at_arc(self, s: np.ndarray) -> np.ndarray:
        """Positions [T, 3] at arc lengths s."""
        u = self._u_of_s(np.clip(s, 0.0, self.length)) if self.length > 0 else np.zeros(np.shape(s))
        return catmull_rom(self.vertices, np.clip(u, 0.0, len(self.vertices) - 1))

    def lateral(self, t: np.ndarray) -> np.ndarray:
        """Centripetal acceleration [T, 3] of the agent at t: v(t)^2 times the spline's
        curvature vector (p'' - (p''.T) T) / |p'|^2, derivatives in u by central differences."""
        s = self.arc(t)
        u = np.clip(self._u_of_s(s), 0.0, len(self.vertices) - 1)
        du = 1e-4
        lo = np.clip(u - du, 0.0, len(self.vertices) - 1)
        hi = np.clip(u + du, 0.0, len(self.vertices) - 1)
        mid = (lo + hi) / 2
        half = ((hi - lo) / 2)[:, None]
        pa, pm, pb = catmull_rom(self.vertices, lo), catmull_rom(self.vertices, mid), catmull_rom(self.vertices, hi)
        d1 = (pb - pa) / (2 * half)
        d2 = (pb - 2 * pm + pa) / (half * half)
        speed2 = np.einsum("ij,ij->i", d1, d1)[:, None]
        tangent = d1 / np.sqrt(np.maximum(speed2, 1e-24))
        curvature = (d2 - np.einsum("ij,ij->i", d2, tangent)[:, None] * tangent) / np.maximum(speed2, 1e-24)
        v = self.speed_at(t)[:, None]
        return v * v * curvature

    def speed_at(self, t: np.ndarray) -> np.ndarray:
        """ds/dt (m/s) of the trapezoid at times t."""
        v, t_a, t_c, t_b = self.profile()
        tau = np.asarray(t, dtype=np.float64) - self.start_time
        out = np.where(tau < t_a, self.accel * tau, np.where(tau < t_a + t_c, v, v - self.decel * (tau - t_a - t_c)))
        return np.where((tau <= 0) | (tau >= t_a + t_c + t_b), 0.0, np.maximum(out, 0.0))

    def position(self, t: np.ndarray) -> np.ndarray:
        """Position [T, 3] on the path at times t (s)."""
        return self.at_arc(self.arc(t))

    def tangent(self, t: np.ndarray) -> np.ndarray:
        """Unit tangent [T, 3] of the path where the agent is at t (defined at rest too)."""
        s = self.arc(t)
        ds = max(1e-4, self.length * 1e-6)
        a = self.at_arc(np.clip(s - ds, 0.0, self.length))
        b = self.at_arc(np.clip(s + ds, 0.0, self.length))
        d = b - a
        return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)

    def samples(self) -> np.ndarray:
        """The dense samples of the arc-length table [K, 3]."""
        return catmull_rom(self.vertices, self.table_u)


def _arc_table(vertices: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, s, du/ds): global parameters at most about `spacing` apart along the curve, the
    cumulative length (chords of the samples) and the exact du/ds = 1 / |dp/du| there.
    Each segment is sampled on its own closed interval (its end a hair before the next
    segment's start), so the jump of dp/du at a vertex is kept, not smoothed over."""
    chords = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    us, dus = [], []
    eps = 1e-9
    for k, c in enumerate(chords):
        n = max(8, int(math.ceil(1.5 * c / spacing)))
        u = k + np.linspace(0.0, 1.0 - eps, n + 1)
        lo, hi = np.maximum(u - 1e-5, k), np.minimum(u + 1e-5, k + 1 - eps)
        d = (catmull_rom(vertices, hi) - catmull_rom(vertices, lo)) / (hi - lo)[:, None]
        us.append(u)
        dus.append(1.0 / np.maximum(np.linalg.norm(d, axis=1), 1e-12))
    us.append(np.array([float(len(vertices) - 1)]))
    dus.append(dus[-1][-1:])
    u = np.concatenate(us)
    p = catmull_rom(vertices, u)
    s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))
    return u, s, np.concatenate(dus)


MAX_INFLATE_WORK = 200_000_000  # grid cells x the cells within an agent's reach (a few seconds)
MAX_PATH_VERTICES = 4096  # vertices the spline refinement may reach before the plan is refused


def build_path(grid: Grid, points: Sequence[Sequence[float]], radius: float, tolerance: float, margin: float,
               speed: float, accel: float, decel: float, start_time: float, facing: str) -> PlannedPath:
    """Plan through `points` (start, waypoints..., goal; world x, y, z). Raises _Located."""
    need_plan = radius + tolerance + margin
    need_path = radius + tolerance
    reach = 2 * (int(math.ceil(need_plan / grid.cell)) + 1) + 1
    if grid.wall.size * reach * reach > MAX_INFLATE_WORK:
        # inflating the walls compares every cell with every cell within reach: a 200 m agent
        # on a 2 m grid of 250,000 cells took 36 s and 10 GB
        raise _Located(("radius",), f"an agent of radius {radius} m (+ tolerance and margin) on cells of {grid.cell} m reaches {reach} x {reach} cells "
                                    f"around each of {grid.wall.size}: over the budget of {MAX_INFLATE_WORK} (a coarser grid cell, or a smaller grid)")
    blocked = grid.blocked(need_plan)
    pts = np.asarray(points, dtype=np.float64)
    names = ["start"] + [f"waypoints[{k}]" for k in range(len(pts) - 2)] + ["goal"]
    loc_of = {"start": ("start",), "goal": ("goal",)}
    cells_at = []
    for name, p in zip(names, pts):
        r, c = grid.cell_of(p[[0, 2]])
        loc = loc_of.get(name, ("waypoints", int(name[10:-1])) if name.startswith("waypoints") else (name,))
        if not (0 <= r < grid.wall.shape[0] and 0 <= c < grid.wall.shape[1]):
            raise _Located(loc, f"{name} {_xyz(p)} is outside the grid")
        if blocked[r, c]:
            clear = float(grid.clearance(p[[0, 2]][None], need_plan + grid.cell)[0])
            raise _Located(loc, f"{name} {_xyz(p)} is {clear:.3g} m from a wall; the agent needs {need_plan:.3g} m (radius + tolerance + margin)")
        cells_at.append((int(r), int(c)))
    legs: list[np.ndarray] = []
    all_cells, costs = [], []
    for k in range(len(pts) - 1):
        found = astar(blocked, cells_at[k], cells_at[k + 1])
        if found is None:
            raise _Located((), f"no path from {names[k]} {_xyz(pts[k])} to {names[k + 1]} {_xyz(pts[k + 1])} for an agent of radius {radius} m "
                           f"(clearance {need_plan:.3g} m with tolerance and margin) on the grid")
        cells, cost = found
        all_cells.append(cells)
        costs.append(cost * grid.cell)
        rc = np.asarray(cells)
        xz = grid.centres(rc[:, 0], rc[:, 1])
        xz[0], xz[-1] = pts[k, [0, 2]], pts[k + 1, [0, 2]]
        short = shorten(grid, xz, need_plan)
        # heights: linear along the leg's 2D length between its two given points
        along = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(short, axis=0), axis=1))))
        f = along / along[-1] if along[-1] > 0 else np.zeros_like(along)
        y = pts[k, 1] + f * (pts[k + 1, 1] - pts[k, 1])
        leg = np.column_stack((short[:, 0], y, short[:, 1]))
        legs.append(leg if k == 0 else leg[1:])
    vertices = np.concatenate(legs)
    if len(vertices) == 1:
        vertices = np.concatenate((vertices, vertices + [1e-9, 0.0, 0.0]))
    spacing = grid.cell / 16.0
    for _ in range(16):
        u, s, duds = _arc_table(vertices, spacing)
        p = catmull_rom(vertices, u)
        gaps = np.concatenate(([0.0], np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1)))
        slack = np.maximum(gaps, np.roll(gaps, -1)) / 2
        bad = grid.clearance(p[:, [0, 2]], need_path + spacing) < need_path + slack
        if not bad.any():
            return PlannedPath(vertices, u, s, duds, all_cells, costs, speed, accel, decel, start_time, facing, grid, need_path)
        segs = np.unique(np.clip(np.floor(u[bad]).astype(np.int64), 0, len(vertices) - 2))
        if len(vertices) + len(segs) > MAX_PATH_VERTICES:
            break  # each round may double the vertices (margin 0 in a corridor did, 42 -> 100,904): stop while it is cheap
        mids = (vertices[segs] + vertices[segs + 1]) / 2
        vertices = np.insert(vertices, segs + 1, mids, axis=0)
    raise _Located((), f"the smoothed path keeps coming closer than {need_path:.3g} m to a wall; give a larger margin "
                       f"(now {margin:g} m: the spline needs room beside the polyline to round its corners)")


# --- from the scene -----------------------------------------------------------------------


def _grid(loaded: "LoadedScene", name: str, spec: Any) -> Grid:
    g = spec.grid
    if g.image is not None:
        return grid_from_image(loaded.asset(g.image), g.cell, g.origin, g.threshold)
    return grid_from_scene(loaded, name, g.cell, g.origin, g.size, g.band)


_PLANS: dict[tuple[str, int, str, int], PlannedPath] = {}


def plan_for(loaded: "LoadedScene", index: int) -> PlannedPath:
    """The planned path of object `index` (a SceneError, located, when there is none).
    Cached per (scene file, object, motion block, grid image mtime)."""
    obj = loaded.scene.objects[index]
    spec = obj.motion
    image_mtime = 0
    if spec.grid.image is not None:
        try:
            image_mtime = loaded.asset(spec.grid.image).stat().st_mtime_ns
        except OSError:
            image_mtime = -1
    key = (str(loaded.path), index, spec.model_dump_json(), image_mtime)
    if key in _PLANS:
        return _PLANS[key]
    loc = ("objects", index, "motion")
    try:
        grid = _grid(loaded, obj.name, spec)
        tolerance = spec.follower.tolerance if spec.follower is not None else 0.0
        margin = spec.margin if spec.margin is not None else spec.grid.cell
        points = [spec.start, *spec.waypoints, spec.goal]
        path = build_path(grid, points, spec.radius, tolerance, margin, spec.speed, spec.accel,
                          spec.decel if spec.decel is not None else spec.accel, spec.start_time, spec.facing)
    except _Located as exc:
        raise SceneError([loaded.source.problem((*loc, *exc.loc), f"{obj.name}: {exc}")]) from None
    except (ValueError, OSError, GridTooLargeError) as exc:
        raise SceneError([loaded.source.problem((*loc, "grid"), f"{obj.name}: {exc}")]) from None
    if len(_PLANS) > 32:
        _PLANS.clear()
    _PLANS[key] = path
    return path


# --- poses --------------------------------------------------------------------------------


def facing_quat(forward: np.ndarray, lateral: np.ndarray | None, g: float) -> np.ndarray:
    """world_from_agent quaternions [T, 4]: local +Z along the horizontal part of `forward`,
    +Y up; with `lateral` (the acceleration across the heading, m/s^2), rolled about the
    heading by atan(|a_lat| / g) so the top leans into the turn."""
    f = forward - (forward @ UP)[:, None] * UP
    norm = np.linalg.norm(f, axis=1, keepdims=True)
    f = np.where(norm > 1e-9, f / np.maximum(norm, 1e-12), np.array([0.0, 0.0, 1.0]))
    side = np.cross(UP, f)
    m = np.stack((side, np.broadcast_to(UP, f.shape), f), axis=-1)
    q = Rotation.from_matrix(m).as_quat(scalar_first=True)
    if lateral is not None:
        across = np.einsum("ij,ij->i", lateral, side)
        # R_z(phi) takes +Y to (-sin phi, cos phi): leaning towards +X (side) is phi < 0
        phi = -np.arctan2(across, g)
        roll = np.stack((np.cos(phi / 2), np.zeros_like(phi), np.zeros_like(phi), np.sin(phi / 2)), axis=1)
        q = quat_mul(q, roll)
    return q


def kinematic_pose(loaded: "LoadedScene", index: int, t: np.ndarray) -> Pose:
    """world_from_object of a planned object that moves exactly along its path."""
    path = plan_for(loaded, index)
    obj = loaded.scene.objects[index]
    x = path.position(t)
    lateral = path.lateral(t) if path.facing == "bank" else None
    return _pose(obj, path, t, x, path.tangent(t), lateral, loaded)


def _pose(obj: Any, path: PlannedPath, t: np.ndarray, x: np.ndarray, forward: np.ndarray, lateral: np.ndarray | None, loaded: "LoadedScene") -> Pose:
    own = np.broadcast_to(transform_quat(obj.transform.rotate), (len(t), 4))
    if path.facing == "none":
        q = own.copy()
    else:
        g = float(np.linalg.norm(loaded.scene.dynamics.gravity)) or 9.81
        q = quat_mul(facing_quat(forward, lateral, g), own)
    return Pose(x, q, np.broadcast_to(np.asarray(obj.transform.scale, dtype=np.float64), (len(t), 3)).copy())


# --- the follower's pose (simulated by the dynamics stage, dynamics/follower.py) ----------


def follower_pose(loaded: "LoadedScene", index: int, track: Any, t: np.ndarray) -> Pose:
    """world_from_object of a planned object carried by its simulated follower (`track`:
    dynamics/follower.py FollowerTrack, whose `at(t)` gives x, v, a): facing along its
    own velocity (the path's tangent when nearly still), banking by its own lateral
    acceleration."""
    path = plan_for(loaded, index)
    obj = loaded.scene.objects[index]
    x, v, a = track.at(t)
    horizontal = v - (v @ UP)[:, None] * UP
    slow = np.linalg.norm(horizontal, axis=1) < 0.05
    forward = np.where(slow[:, None], path.tangent(t), v)
    lateral = a if path.facing == "bank" else None
    return _pose(obj, path, t, x, forward, lateral, loaded)
