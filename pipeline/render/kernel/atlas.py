"""The rest-frame atlas: every moving thing's geometry in ONE Mitsuba scene, each apart.

A rigid mover is intersected in its rest frame at the ray's own time (render/kernel/world.py).
Instead of one small scene per mover (one trace site each in the kernel), every mover's
rest-frame shapes, and one holder sphere per particle system, live in a single scene: the
atlas. Each *template* (a mover, or a particle system's holder) sits in its own cell of a
3D grid, moved there by an offset; the cells' padded boxes never overlap. A ray mapped
into a template's rest frame is moved by the template's offset and clipped to its box, so
it can only meet that template's shapes: one trace site serves every mover, whatever
their number. Templates of the same shapes (the same kind, rest-frame placement and
material) share one cell and one copy of the shapes; each keeps its own row of the layout.

Scale (and a mover's other per-frame shape changes) is baked into the template's shapes;
when a mover's scale changes the atlas is laid out and built again (rare: keyed scale).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

# the gap between cells and the padding of each template's box, as fractions of the cell:
# a ray clipped to the padded box starts before any shape touching the box's faces
PAD = 1e-3
GAP = 0.25
# each cell holds three times the largest template: a mover whose keyed scale grows up to that
# is replaced in place (`Atlas.replace`), beyond it the atlas is laid out again
HEADROOM = 3.0


@dataclass(frozen=True)
class Layout:
    """Where each of T templates sits in the atlas: `offset` [T, 3] added to its rest-frame
    points, `box` [T, 2, 3] its padded box in the atlas (min, max), and `sphere` [T, 4] its
    rest-frame bounding sphere (centre, radius), which the kernel poses at the ray's time
    as an exact prefilter."""

    offset: np.ndarray
    box: np.ndarray
    sphere: np.ndarray
    centre: np.ndarray  # [T, 3] the centre of each template's cell
    cell: float = 1.0  # the cells' edge


def lay_out(boxes: np.ndarray, spheres: np.ndarray) -> Layout:
    """A layout for templates with rest-frame boxes [T, 2, 3] (min, max) and bounding
    spheres [T, 4]: a cubic grid of equal cells, each template's box centred in its cell.
    The cell's edge is three times the largest box extent (`HEADROOM`) plus a gap, so padded boxes
    never overlap, also after a template grows in place;
    the grid is centred on the origin so atlas coordinates stay small (float precision)."""
    count = len(boxes)
    if count == 0:
        return Layout(np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros((0, 4)), np.zeros((0, 3)))
    lo, hi = boxes[:, 0], boxes[:, 1]
    extent = float(np.max(hi - lo)) if count else 1.0
    cell = max(extent, 1e-6) * HEADROOM * (1.0 + GAP) + 1e-4
    side = int(np.ceil(count ** (1.0 / 3.0) - 1e-9))
    while side**3 < count:
        side += 1
    k = np.arange(count)
    grid = np.stack([k % side, (k // side) % side, k // (side * side)], axis=1).astype(float)
    centres = (grid - (side - 1) / 2.0) * cell
    offset = centres - (lo + hi) / 2.0
    pad = PAD * cell + 1e-5
    box = np.stack([lo + offset - pad, hi + offset + pad], axis=1)
    return Layout(offset, box, np.asarray(spheres, dtype=float), centres, cell)


def translate_shape(mi: Any, shape: Any, offset: np.ndarray) -> None:
    """Move a built Mitsuba shape by `offset` (a mesh's vertices, another shape's to_world).

    The new values are computed on the host and written opaque: the shape's update kernel
    is then the same for every template, compiled once (with the offset as literals, each
    template's update would be a kernel of its own: docs/rendering.md)."""
    import drjit as dr

    params = mi.traverse(shape)
    if "vertex_positions" in params:  # a triangle mesh (a rectangle reads as a mesh to is_mesh, with a to_world)
        v = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3) + offset
        params["vertex_positions"] = mi.Float(np.asarray(v, np.float32).ravel())
    else:
        matrix = np.array(params["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        moved = mi.Transform4f(mi.ScalarTransform4f().translate([float(c) for c in offset]) @ mi.ScalarTransform4f(matrix))
        dr.make_opaque(moved)
        params["to_world"] = moved
    params.update()


def analytic(dicts: Sequence[dict[str, Any]]) -> bool:
    """Whether every shape dictionary of a template is an analytic shape placed only by its
    to_world (a sphere, a cube, a rectangle, a disk, a cylinder: Mitsuba's unit shapes), so
    that it can be bounded from the dictionary and built in the atlas already moved; a mesh
    read from a file is not (its vertices carry its placement)."""
    return bool(dicts) and all(d.get("type") in _UNIT_BOX or d.get("type") == "sphere" for d in dicts) and all(
        hasattr(d.get("to_world"), "matrix") for d in dicts)


def settle() -> None:
    """Wait for the shapes' updates still queued on drjit's thread pool (`translate_shape`'s
    parameter updates run as asynchronous kernels): Mitsuba's scene build reads a moved
    mesh, and must not read it before its update has run, or a mover's triangles go
    missing (docs/rendering.md, "One traversal for everything that moves")."""
    import drjit as dr

    dr.sync_thread()


def copy_shape(mi: Any, params: Any, prefix: str, shape: Any) -> list[str]:
    """Write a built shape's placement into the shape named `prefix` of a scene's
    parameters (its to_world, or a mesh's vertices and normals, which hold its transform):
    the scene and its variables stay, so the kernels that trace it are replayed. Returns the
    keys written."""
    fresh = mi.traverse(shape)
    keys = [k for k in ("to_world", "vertex_positions", "vertex_normals") if k in fresh and f"{prefix}.{k}" in params]
    for k in keys:
        params[f"{prefix}.{k}"] = fresh[k]
    return [f"{prefix}.{k}" for k in keys]


def bounds(shapes: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box (min, max) of built shapes and their bounding sphere (centre, radius)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for s in shapes:
        b = s.bbox()
        lo = np.minimum(lo, np.array(b.min, dtype=float).ravel())
        hi = np.maximum(hi, np.array(b.max, dtype=float).ravel())
    if not shapes:
        lo, hi = np.zeros(3), np.zeros(3)
    centre = (lo + hi) / 2
    reach = max((shape_sphere(s, centre) for s in shapes), default=0.0)
    return lo, hi, np.array([*centre, reach * (1 + 1e-4) + 1e-5])


def points_sphere(points: np.ndarray) -> np.ndarray:
    """A sphere (centre, radius) [4] holding `points` [P, 3]: their box's centre and the
    farthest point from it, padded as `bounds` pads (zeros for no points)."""
    if len(points) == 0:
        return np.zeros(4)
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    return np.array([*centre, float(np.sqrt(((points - centre) ** 2).sum(axis=1).max())) * (1 + 1e-4) + 1e-5])


# The box of each analytic shape in its own frame, before its to_world (Mitsuba's unit
# shapes: the cube [-1, 1]^3, the rectangle and the disk in z = 0, the cylinder from z = 0
# to 1 of radius 1); a sphere is bounded by its centre and radius instead.
_UNIT_BOX = {"cube": ((-1, -1, -1), (1, 1, 1)), "rectangle": ((-1, -1, 0), (1, 1, 0)), "disk": ((-1, -1, 0), (1, 1, 0)), "cylinder": ((-1, -1, 0), (1, 1, 1))}


def dict_bounds(dicts: Sequence[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`bounds` of analytic shapes from their dictionaries (`analytic`), none
    built: a sphere's centre and its largest axis as radius, another shape's unit box's
    corners through its to_world (its convex hull holds the shape). At 1,000 movers, building
    each shape once only to bound it cost 0.1 s of the first frame."""
    lows, highs, parts = [], [], []
    for d in dicts:
        m = np.array(d["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        if d["type"] == "sphere":
            c, r = m[:3, 3], float(np.linalg.norm(m[:3, :3], axis=0).max())
            lows.append(c - r)
            highs.append(c + r)
            parts.append(("sphere", c, r))
        else:
            lo, hi = _UNIT_BOX[d["type"]]
            corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) @ m.T
            lows.append(corners[:, :3].min(axis=0))
            highs.append(corners[:, :3].max(axis=0))
            parts.append(("points", corners[:, :3], 0.0))
    if not dicts:
        return np.zeros(3), np.zeros(3), np.zeros(4)
    lo, hi = np.min(lows, axis=0), np.max(highs, axis=0)
    centre = (lo + hi) / 2
    reach = max(float(np.linalg.norm(c - centre)) + r if kind == "sphere" else float(np.sqrt(((c - centre) ** 2).sum(axis=1).max())) for kind, c, r in parts)
    return lo, hi, np.array([*centre, reach * (1 + 1e-4) + 1e-5])


def _sharing_key(dicts: Sequence[dict[str, Any]]) -> tuple[Any, ...] | None:
    """What makes two templates of analytic shapes the same in their rest frames: each
    shape's kind, to_world and material (the very BSDF the job built); None for a template
    that keeps a cell of its own (an emitter, a material given inline, anything else)."""
    out = []
    for d in dicts:
        if set(d) != {"type", "to_world", "bsdf"} or isinstance(d["bsdf"], (dict, str)):
            return None
        out.append((d["type"], tuple(np.array(d["to_world"].matrix, dtype=np.float64).ravel()), id(d["bsdf"])))
    return tuple(out)


def _cells(templates: Sequence[Sequence[Any] | None], dicts: Sequence[Sequence[dict[str, Any]] | None] | None) -> list[int]:
    """Each template's cell, named by the first template of the same shapes (itself when
    it shares with none): templates given as dictionaries only (analytic) share."""
    first: dict[tuple[Any, ...], int] = {}
    out = []
    for t, shapes in enumerate(templates):
        key = _sharing_key(dicts[t]) if shapes is None and dicts is not None and dicts[t] is not None else None  # type: ignore[arg-type]
        out.append(first.setdefault(key, t) if key is not None else t)
    return out


def shape_sphere(shape: Any, centre: np.ndarray) -> float:
    """The farthest any point of a built shape lies from `centre` (an upper bound): a
    mesh's farthest vertex, a sphere's own radius, otherwise its box's farthest corner."""
    import mitsuba as mi

    box = shape.bbox()
    lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
    if shape.is_mesh() and "vertex_positions" in mi.traverse(shape):
        vertices = np.array(shape.vertex_positions_buffer(), dtype=float).reshape(-1, 3)
        if len(vertices):
            return float(np.sqrt(((vertices - centre) ** 2).sum(axis=1).max()))
    elif shape.shape_type() == int(mi.ShapeType.Sphere):
        return float(np.linalg.norm((lo + hi) / 2 - centre) + (hi[0] - lo[0]) / 2)
    return float(np.linalg.norm(np.maximum(np.abs(lo - centre), np.abs(hi - centre))))


class Atlas:
    """The atlas scene of one job: templates (lists of built rest-frame shapes, one list per
    mover or particle holder) laid out apart in one scene. `make_scene` builds a scene
    dictionary (the job's SBT owner's `scene`, render/kernel/sbt.py)."""

    def __init__(self, mi: Any, make_scene: Callable[[dict[str, Any]], Any]) -> None:
        self._mi = mi
        self._make_scene = make_scene
        self.scene: Any = None
        self.layout = lay_out(np.zeros((0, 2, 3)), np.zeros((0, 4)))
        self.cell_of: list[int] = []  # each template's cell, named by its first template
        self._sharing: collections.Counter[int] = collections.Counter()

    def build(self, templates: Sequence[Sequence[Any] | None], keys: Sequence[str], dicts: Sequence[Sequence[dict[str, Any]] | None] | None = None) -> None:
        """Lay out and build the atlas; `keys` name each template's shapes in the scene
        dictionary. A template given as its shape dictionaries only (`dicts`, with None for
        its built shapes: analytic shapes placed by their to_world, `analytic`) is bounded
        from them and goes into the scene as those dictionaries with the cell's offset in
        front of their to_world, built with the scene; any other is given built, bounded
        from its shapes and moved in place (`translate_shape`: a mesh's vertices). At 1,000
        movers, moving each shape in place cost half a second of the first frame.

        Templates of the same shapes in their rest frames (`_sharing_key`: a crowd's agents,
        debris of a few kinds, a grid of the same ball) share one cell and one copy of their
        shapes: each keeps its own row of the layout (the kernel reads a proxy's template by
        its own index), with the cell's offset and box."""
        self.cell_of = _cells(templates, dicts)
        cells = sorted(set(self.cell_of))
        boxes, spheres = [], []
        for t in cells:
            lo, hi, sphere = bounds(templates[t]) if templates[t] is not None else dict_bounds(dicts[t])  # type: ignore[arg-type, index]
            boxes.append((lo, hi))
            spheres.append(sphere)
        laid = lay_out(np.asarray(boxes, dtype=float).reshape(-1, 2, 3), np.asarray(spheres, dtype=float).reshape(-1, 4))
        place = {c: i for i, c in enumerate(cells)}
        row = np.array([place[c] for c in self.cell_of], dtype=int)
        self.layout = Layout(laid.offset[row], laid.box[row], laid.sphere[row], laid.centre[row], laid.cell)  # (copies: a template's row changes alone)
        self._sharing = collections.Counter(self.cell_of)
        d: dict[str, Any] = {"type": "scene"}
        for t, (shapes, key) in enumerate(zip(templates, keys)):
            if self.cell_of[t] != t:
                continue  # its cell's shapes are another template's
            if shapes is None:
                moved = self._mi.ScalarTransform4f().translate([float(c) for c in self.layout.offset[t]])
                for k, sd in enumerate(dicts[t]):  # type: ignore[index]
                    d[f"{key}__{k}"] = {**sd, "to_world": moved @ sd["to_world"]}
                continue
            for k, s in enumerate(shapes):
                translate_shape(self._mi, s, self.layout.offset[t])
                d[f"{key}__{k}"] = s
        if len(d) == 1:  # an empty atlas still needs a shape to be a scene the kernel can trace
            d["atlas_empty"] = {"type": "sphere", "radius": 1e-6, "to_world": self._mi.ScalarTransform4f().translate([0.0, 0.0, -1e9])}
        settle()
        self.scene = self._make_scene(d)
        self.keys = list(keys)
        self._params = self._mi.traverse(self.scene)

    def replace(self, template: int, shapes: Sequence[Any]) -> bool:
        """Put new shapes (a mover at a new scale) in place of template `template`'s, in the
        same scene and cell: written through its parameters, so the kernels are replayed.
        False where they do not fit the cell (the caller then builds the atlas again)."""
        layout = self.layout
        if self._sharing.get(self.cell_of[template], 1) > 1:
            return False  # its cell holds other templates' shapes too: it gets a cell of its own
        lo, hi, sphere = bounds(shapes)
        pad = PAD * layout.cell + 1e-5
        if np.any(hi - lo + 2 * pad > layout.cell / (1.0 + GAP)):
            return False
        offset = layout.centre[template] - (lo + hi) / 2
        for s in shapes:
            translate_shape(self._mi, s, offset)
        settle()
        for k, s in enumerate(shapes):
            if not copy_shape(self._mi, self._params, f"{self.keys[template]}__{k}", s):
                return False
        self._params.update()
        layout.offset[template] = offset
        layout.box[template] = (lo + offset - pad, hi + offset + pad)
        layout.sphere[template] = sphere
        return True

    def reshape(self, template: int, positions: np.ndarray, normals: np.ndarray | None) -> bool:
        """Write new vertices (a deforming mesh's residual, render/translate/deforming.py) into template
        `template`'s one mesh, recentred in its cell, with its box and bounding sphere;
        written through the scene's parameters (the kernels are replayed), built by
        `commit`. False where they do not fit the cell (the caller builds the atlas again)."""
        layout = self.layout
        if len(positions) == 0:
            return True
        lo, hi = positions.min(axis=0), positions.max(axis=0)
        pad = PAD * layout.cell + 1e-5
        if np.any(hi - lo + 2 * pad > layout.cell / (1.0 + GAP)):
            return False
        offset = layout.centre[template] - (lo + hi) / 2
        prefix = f"{self.keys[template]}__0"
        self._params[f"{prefix}.vertex_positions"] = self._mi.Float(np.asarray(positions + offset, np.float32).ravel())
        if normals is not None and f"{prefix}.vertex_normals" in self._params:
            self._params[f"{prefix}.vertex_normals"] = self._mi.Float(np.asarray(normals, np.float32).ravel())
        layout.offset[template] = offset
        layout.box[template] = (lo + offset - pad, hi + offset + pad)
        layout.sphere[template] = points_sphere(positions)
        return True

    def commit(self) -> None:
        """Build what `reshape` wrote (one parameter update: the atlas's BVH is rebuilt)."""
        self._params.update()
