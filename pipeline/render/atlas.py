"""The rest-frame atlas: every moving thing's geometry in ONE Mitsuba scene, each apart.

A rigid mover is intersected in its rest frame at the ray's own time (render/world.py).
Instead of one small scene per mover (one trace site each in the kernel), every mover's
rest-frame shapes, and one holder sphere per particle system, live in a single scene: the
atlas. Each *template* (a mover, or a particle system's holder) sits in its own cell of a
3D grid, moved there by an offset; the cells' padded boxes never overlap. A ray mapped
into a template's rest frame is moved by the template's offset and clipped to its box, so
it can only meet that template's shapes: one trace site serves every mover, whatever
their number.

Scale (and a mover's other per-frame shape changes) is baked into the template's shapes;
when a mover's scale changes the atlas is laid out and built again (rare: keyed scale).
"""

from __future__ import annotations

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


def _placed_by_transform(d: dict[str, Any]) -> bool:
    """Whether a shape dictionary is an analytic shape placed only by its to_world (a
    sphere, a cube, a rectangle, a disk, a cylinder), so that it can be built again moved;
    a mesh read from a file is not (read again, and its vertices carry its placement)."""
    return d.get("type") in ANALYTIC and "to_world" in d and not isinstance(d["to_world"], (dict, str))


ANALYTIC = frozenset({"sphere", "cube", "rectangle", "disk", "cylinder"})


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
    dictionary (the job's SBT owner's `scene`, render/sbt.py)."""

    def __init__(self, mi: Any, make_scene: Callable[[dict[str, Any]], Any]) -> None:
        self._mi = mi
        self._make_scene = make_scene
        self.scene: Any = None
        self.layout = lay_out(np.zeros((0, 2, 3)), np.zeros((0, 4)))

    def build(self, templates: Sequence[Sequence[Any]], keys: Sequence[str], dicts: Sequence[Sequence[dict[str, Any]] | None] | None = None) -> None:
        """Lay out and build the atlas from each template's built shapes; `keys` name each
        template's shapes in the scene dictionary. A template whose shape dictionaries are
        given (`dicts`, analytic shapes placed by their to_world) goes into the scene as
        those dictionaries with the cell's offset in front of their to_world, built with the
        scene; any other is moved in place (`translate_shape`: a mesh's vertices). At 1,000
        movers the in-place moves cost half a second of the first frame."""
        boxes, spheres = [], []
        for shapes in templates:
            lo, hi, sphere = bounds(shapes)
            boxes.append((lo, hi))
            spheres.append(sphere)
        self.layout = lay_out(np.asarray(boxes, dtype=float).reshape(-1, 2, 3), np.asarray(spheres, dtype=float).reshape(-1, 4))
        d: dict[str, Any] = {"type": "scene"}
        for t, (shapes, key) in enumerate(zip(templates, keys)):
            placed = dicts[t] if dicts is not None and t < len(dicts) else None
            if placed is not None and len(placed) == len(shapes) and all(_placed_by_transform(sd) for sd in placed):
                moved = self._mi.ScalarTransform4f().translate([float(c) for c in self.layout.offset[t]])
                for k, sd in enumerate(placed):
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
