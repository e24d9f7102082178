"""Shape geometry: everything the pipeline knows about a scene `shape`, one entry each.

A scene object's `shape` (sphere, cube, cylinder, capsule ...) is read by three stages:
the renderer (Mitsuba primitives), the dynamics (mass properties, a bounding sphere, a
true-shape contact form, a static collider) and deformation and planning (a tessellated
mesh, an inside test). Each shape answers all of them here, in its own `ShapeGeometry`
entry of `SHAPES`, so a new shape type is one schema record (scene/schema.py) plus one
entry below. Fields a shape cannot answer are None (a disk has no inside), and each
consumer says so in a located error or skips the object, as documented there.

Conventions. Every function takes the scene record (duck-typed: this module sits below
the scene stage and reads only the record's fields) in OBJECT space, before the object's
transform; `measure` alone also takes the transform's scale (a 3-vector), because mass
properties are of the scaled body. Sizes are metres, masses kilograms. Axes: cylinders
and capsules along +Y, centred; rectangles and disks in XY with normal +Z; Mitsuba's
unit primitives are sphere (radius 1), cube ([-1, 1]^3), rectangle and disk ([-1, 1]^2,
unit radius, in XY) and the open cylinder along +Z from z = 0 to 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .errors import ShapeGeometryError, ShapeNotTessellatedError, UnknownShapeError

# true-shape contact forms of rigid bodies (dynamics/shapes.py); 0 is the bounding sphere
BOUND, BOX, CYLINDER = 0, 1, 2

# a point-like thing (an empty) is a small solid sphere of this radius (m): keeps the
# inertia invertible and gives it a bound
POINT_RADIUS = 0.05

Mesh = tuple[np.ndarray, np.ndarray]  # vertices [V, 3], triangles [F, 3]


@dataclass(frozen=True)
class Measure:
    """Mass-property inputs of a scaled body: `dims` for its inertia entry (m), the
    bounding-sphere radius (m) about its centre, its volume (m^3) and, when its drag
    cross-section is a disk of a known radius (a sphere), that radius (else None: the
    disk of the sphere of equal volume)."""

    dims: dict[str, float]
    bound: float
    volume: float
    section: float | None = None


@dataclass(frozen=True)
class Primitive:
    """One Mitsuba shape plugin (`plugin`: sphere, cube, rectangle, disk, cylinder) and the
    4x4 matrix placing its unit primitive in object space."""

    plugin: str
    object_from_prim: np.ndarray


@dataclass(frozen=True)
class ColliderForm:
    """How a static object collides, in object space: `kind` is plane (a rectangle of
    half sizes `half[:2]`), disk (`radius`), box (`half` [3]), sphere (`radius`) or mesh
    (its tessellation or mesh file)."""

    kind: str
    half: np.ndarray | None = None
    radius: float | None = None


@dataclass(frozen=True)
class ShapeGeometry:
    """What one scene shape is to every stage (see the module docstring)."""

    name: str
    # mass properties from the record and its scale ([3]); `mesh` is the file's mesh
    # (vertices, triangles) for shapes with `file_mesh`, else None
    measure: Callable[[Any, np.ndarray, Mesh | None], Measure]
    # principal moments (Ixx, Iyy, Izz), kg m^2, about the object's axes, from `dims`
    inertia: Callable[[float, dict[str, float]], np.ndarray]
    # the Mitsuba primitives of the shape (None: a mesh file, drawn from the file)
    primitives: Callable[[Any], list[Primitive]] | None
    # object-space vertices and triangles at a tessellation `detail` (None: cannot deform)
    tessellate: Callable[[Any, int], Mesh] | None = None
    # object-space points [..., 3] -> inside [...] (planning obstacles; None: not solid)
    inside: Callable[[Any, np.ndarray], np.ndarray] | None = None
    # how a static object of this shape collides (None: it cannot be a collider)
    collider: Callable[[Any], ColliderForm] | None = None
    # a rigid body's true-shape contact form from its `dims`: (BOX | CYLINDER, half
    # extents [3]); None: it collides as its bounding sphere
    contact: Callable[[dict[str, float]], tuple[int, np.ndarray]] | None = None
    file_mesh: bool = False  # the geometry is a mesh file (`file`)


SHAPES: dict[str, ShapeGeometry] = {}


def _register(entry: ShapeGeometry) -> ShapeGeometry:
    SHAPES[entry.name] = entry
    return entry


def shape_geometry(shape: str) -> ShapeGeometry:
    """The geometry entry of the scene shape `shape`."""
    try:
        return SHAPES[shape]
    except KeyError:
        raise UnknownShapeError(f"no geometry for shape {shape!r} (known: {', '.join(SHAPES)})") from None


def principal_inertia(shape: str, mass: float, dims: dict[str, float]) -> np.ndarray:
    """Principal moments (Ixx, Iyy, Izz) in kg m^2 of a body of `shape` about its own axes."""
    return shape_geometry(shape).inertia(mass, dims)


def tessellate(obj: Any, detail: int = 16) -> Mesh:
    """Object-space vertices and triangles of a primitive shape (cube: 6 grids of detail^2
    quads; cylinder: detail rings x 2*detail segments, closed by two fans; rectangle: an XY grid;
    capsule: 2*(detail+1) rings x 2*detail segments). Raises ShapeNotTessellatedError for
    shapes with no tessellation (sphere, disk, empty, particles) and for mesh files."""
    entry = shape_geometry(obj.shape)
    if entry.tessellate is None:
        if entry.file_mesh:
            raise ShapeNotTessellatedError("meshes come from their file")
        can = ", ".join(n for n, e in SHAPES.items() if e.tessellate is not None or e.file_mesh)
        raise ShapeNotTessellatedError(f"deformation of a {obj.shape} is not supported; use one of: {can}")
    return entry.tessellate(obj, detail)


# --- helpers ------------------------------------------------------------------------------


def scale_matrix(sx: float, sy: float, sz: float) -> np.ndarray:
    """diag(sx, sy, sz, 1)."""
    return np.diag([sx, sy, sz, 1.0])


_Z_TO_Y = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # rot -90 about x
_Y_DOWN = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)  # rot +90 about x


def _translate_y(y: float) -> np.ndarray:
    m = np.eye(4)
    m[1, 3] = y
    return m


def _open_cylinder(r: float, h: float) -> Primitive:
    """Mitsuba's open cylinder along +Y, radius r, from y = -h/2 to h/2."""
    return Primitive("cylinder", _translate_y(-h / 2) @ _Z_TO_Y @ scale_matrix(r, r, h))


def grid_rect(nu: int, nv: int) -> Mesh:
    """An (nu+1) x (nv+1) grid on [0, 1]^2: uv [(nu+1)(nv+1), 2] and triangles [2 nu nv, 3]."""
    u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="xy")
    uv = np.stack((u.ravel(), v.ravel()), axis=1)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="xy")
    a = (j * (nu + 1) + i).ravel()
    b, c, d = a + 1, a + nu + 1, a + nu + 2
    return uv, np.concatenate((np.stack((a, b, d), 1), np.stack((a, d, c), 1)))


def _solid_sphere(m: float, r: float) -> np.ndarray:
    i = 0.4 * m * r**2
    return np.array([i, i, i])


def _solid_box(m: float, d: dict[str, float]) -> np.ndarray:
    a, b, c = d["sx"], d["sy"], d["sz"]
    return m / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])


# --- the shapes ---------------------------------------------------------------------------


def _sphere_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    r = o.radius * float(s.max())
    return Measure({"radius": r}, r, 4.0 / 3.0 * math.pi * r**3, section=r)


_register(ShapeGeometry(
    "sphere",
    measure=_sphere_measure,
    inertia=lambda m, d: _solid_sphere(m, d["radius"]),  # 2/5 m r^2
    primitives=lambda o: [Primitive("sphere", scale_matrix(o.radius, o.radius, o.radius))],
    inside=lambda o, p: np.einsum("...i,...i->...", p, p) <= o.radius**2,
    collider=lambda o: ColliderForm("sphere", radius=o.radius),
))


def _cube_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    dims = np.asarray(o.size, dtype=np.float64) * s
    return Measure({"sx": dims[0], "sy": dims[1], "sz": dims[2]}, float(np.linalg.norm(dims)) / 2, float(np.prod(dims)))


def _cube_mesh(o: Any, detail: int) -> Mesh:
    uv, tri = grid_rect(detail, detail)
    size = np.asarray(o.size, dtype=np.float64)
    faces_v, faces_t = [], []
    # each face: a grid in the plane of two axes at +-0.5 along the third
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = [k for k in range(3) if k != axis]
            p = np.zeros((len(uv), 3))
            p[:, axis] = 0.5 * sign
            p[:, a], p[:, b] = uv[:, 0] - 0.5, uv[:, 1] - 0.5
            t = tri if sign > 0 else tri[:, ::-1]
            faces_t.append(t + sum(len(f) for f in faces_v))
            faces_v.append(p * size)
    return np.concatenate(faces_v), np.concatenate(faces_t)


_register(ShapeGeometry(
    "cube",
    measure=_cube_measure,
    inertia=_solid_box,  # m/12 (b^2 + c^2, a^2 + c^2, a^2 + b^2)
    # Mitsuba's cube spans [-1, 1]^3
    primitives=lambda o: [Primitive("cube", scale_matrix(o.size[0] / 2, o.size[1] / 2, o.size[2] / 2))],
    tessellate=_cube_mesh,
    inside=lambda o, p: np.all(np.abs(p) <= np.asarray(o.size, dtype=np.float64) / 2, axis=-1),
    collider=lambda o: ColliderForm("box", half=np.asarray(o.size, dtype=np.float64) / 2),
    contact=lambda d: (BOX, np.array([d["sx"] / 2, d["sy"] / 2, d["sz"] / 2])),
))


def _rectangle_mesh(o: Any, detail: int) -> Mesh:
    uv, tri = grid_rect(detail, detail)
    return np.column_stack(((uv[:, 0] - 0.5) * o.width, (uv[:, 1] - 0.5) * o.height, np.zeros(len(uv)))), tri


def _rectangle_inertia(m: float, d: dict[str, float]) -> np.ndarray:
    w, h = d["width"], d["height"]
    return m / 12.0 * np.array([h * h, w * w, w * w + h * h])


def _rectangle_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    w, h = o.width * s[0], o.height * s[1]
    return Measure({"width": w, "height": h}, math.hypot(w, h) / 2, 0.0)


_register(ShapeGeometry(
    "rectangle",
    measure=_rectangle_measure,
    # thin rectangle in XY: m/12 (h^2, w^2, w^2 + h^2)
    inertia=_rectangle_inertia,
    # Mitsuba's rectangle spans [-1, 1]^2 in XY, normal +Z
    primitives=lambda o: [Primitive("rectangle", scale_matrix(o.width / 2, o.height / 2, 1.0))],
    tessellate=_rectangle_mesh,
    collider=lambda o: ColliderForm("plane", half=np.array([o.width / 2, o.height / 2, 0.0])),
))


def _disk_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    r = o.radius * float(s[:2].max())
    return Measure({"radius": r}, r, 0.0)


_register(ShapeGeometry(
    "disk",
    measure=_disk_measure,
    inertia=lambda m, d: m * d["radius"] * d["radius"] * np.array([0.25, 0.25, 0.5]),  # disk in XY
    primitives=lambda o: [Primitive("disk", scale_matrix(o.radius, o.radius, 1.0))],
    collider=lambda o: ColliderForm("disk", radius=o.radius),
))


def _cylinder_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    r, h = o.radius * float(max(s[0], s[2])), o.height * s[1]
    return Measure({"radius": r, "height": h}, math.hypot(r, h / 2), math.pi * r * r * h)


def _cylinder_inertia(m: float, d: dict[str, float]) -> np.ndarray:
    """Along +Y: Iyy = m r^2 / 2, Ixx = Izz = m (3 r^2 + h^2) / 12."""
    r, h = d["radius"], d["height"]
    side = m * (3 * r * r + h * h) / 12.0
    return np.array([side, 0.5 * m * r * r, side])


def _cylinder_primitives(o: Any) -> list[Primitive]:
    # the open side, closed with two disks (top facing +Y, bottom facing -Y)
    r, h = o.radius, o.height
    top = _translate_y(h / 2) @ _Z_TO_Y @ scale_matrix(r, r, 1.0)
    bottom = _translate_y(-h / 2) @ _Y_DOWN @ scale_matrix(r, r, 1.0)
    return [_open_cylinder(r, h), Primitive("disk", top), Primitive("disk", bottom)]


def _cylinder_mesh(o: Any, detail: int) -> Mesh:
    # the side grid, closed by two fans about the cap centres (outward: +Y on top)
    segments = 2 * detail
    uv, tri = grid_rect(segments, detail)
    theta = 2 * np.pi * uv[:, 0]
    side = np.column_stack((o.radius * np.cos(theta), (uv[:, 1] - 0.5) * o.height, -o.radius * np.sin(theta)))
    top, bottom = len(side), len(side) + 1
    k = np.arange(segments)
    top_ring, bottom_ring = detail * (segments + 1) + k, k
    caps = np.concatenate((
        np.column_stack((np.full(segments, top), top_ring, top_ring + 1)),
        np.column_stack((np.full(segments, bottom), bottom_ring + 1, bottom_ring)),
    ))
    centres = np.array([[0.0, o.height / 2, 0.0], [0.0, -o.height / 2, 0.0]])
    return np.concatenate((side, centres)), np.concatenate((tri, caps))


_register(ShapeGeometry(
    "cylinder",
    measure=_cylinder_measure,
    inertia=_cylinder_inertia,
    primitives=_cylinder_primitives,
    tessellate=_cylinder_mesh,
    inside=lambda o, p: (p[..., 0] ** 2 + p[..., 2] ** 2 <= o.radius**2) & (np.abs(p[..., 1]) <= o.height / 2),
    contact=lambda d: (CYLINDER, np.array([d["radius"], d["height"] / 2, d["radius"]])),
))


def _capsule_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    r, h = o.radius * float(max(s[0], s[2])), o.height * s[1]
    return Measure({"radius": r, "height": h}, h / 2 + r, math.pi * r * r * h + 4.0 / 3.0 * math.pi * r**3)


def _capsule_inertia(m: float, d: dict[str, float]) -> np.ndarray:
    """A solid cylinder (radius r, length h, along +Y) capped by two hemispheres, mass
    shared by volume (m_c cylinder, m_s both caps). Iyy = m_c r^2/2 + 2/5 m_s r^2;
    Ixx = Izz = m_c (r^2/4 + h^2/12) + m_s (2/5 r^2 + h^2/4 + 3 h r / 8) (each cap:
    83/320 m r^2 about its centre of mass, 3 r / 8 from its flat face, moved by
    parallel axes to the capsule's centre)."""
    r, h = d["radius"], d["height"]
    v_c, v_s = math.pi * r * r * h, 4.0 / 3.0 * math.pi * r**3
    m_c = m * v_c / (v_c + v_s)
    m_s = m - m_c
    side = m_c * (r * r / 4 + h * h / 12) + m_s * (0.4 * r * r + h * h / 4 + 3 * h * r / 8)
    return np.array([side, 0.5 * m_c * r * r + 0.4 * m_s * r * r, side])


def _capsule_mesh(o: Any, detail: int) -> Mesh:
    # profile from the bottom pole to the top pole: a quarter circle under y = -h/2, one
    # over y = +h/2; revolved about +Y with the cylinder's orientation
    r, h = o.radius, o.height
    phi = np.linspace(0.0, math.pi / 2, detail + 1)
    ring_r = np.concatenate((np.sin(phi), np.cos(phi))) * r
    ring_y = np.concatenate((-h / 2 - r * np.cos(phi), h / 2 + r * np.sin(phi)))
    rings = len(ring_r)
    uv, tri = grid_rect(2 * detail, rings - 1)
    theta = 2 * np.pi * uv[:, 0]
    row = np.rint(uv[:, 1] * (rings - 1)).astype(int)
    return np.column_stack((ring_r[row] * np.cos(theta), ring_y[row], -ring_r[row] * np.sin(theta))), tri


def _capsule_inside(o: Any, p: np.ndarray) -> np.ndarray:
    # within `radius` of the axis segment from y = -h/2 to h/2
    y = np.clip(p[..., 1], -o.height / 2, o.height / 2)
    return p[..., 0] ** 2 + (p[..., 1] - y) ** 2 + p[..., 2] ** 2 <= o.radius**2


_register(ShapeGeometry(
    "capsule",
    measure=_capsule_measure,
    inertia=_capsule_inertia,
    primitives=lambda o: [
        _open_cylinder(o.radius, o.height),
        Primitive("sphere", _translate_y(o.height / 2) @ scale_matrix(o.radius, o.radius, o.radius)),
        Primitive("sphere", _translate_y(-o.height / 2) @ scale_matrix(o.radius, o.radius, o.radius)),
    ],
    tessellate=_capsule_mesh,
    inside=_capsule_inside,
    collider=lambda o: ColliderForm("mesh"),
))


def _mesh_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    if mesh is None:
        raise ShapeGeometryError(f"the mass properties of mesh '{o.file}' need its vertices")
    verts, tris = mesh
    verts = verts * s
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    # closed-mesh volume: sum of signed tetrahedra (0, a, b, c) = a . (b x c) / 6
    tri = verts[tris]
    vol = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0)
    dims = hi - lo
    return Measure({"sx": dims[0], "sy": dims[1], "sz": dims[2]}, float(np.linalg.norm(verts, axis=1).max()), vol or float(np.prod(dims)))


_register(ShapeGeometry(
    "mesh",
    measure=_mesh_measure,
    inertia=_solid_box,  # the solid box of its bounds
    primitives=None,
    collider=lambda o: ColliderForm("mesh"),
    file_mesh=True,
))


def _point_measure(o: Any, s: np.ndarray, mesh: Mesh | None) -> Measure:
    return Measure({}, POINT_RADIUS, 4.0 / 3.0 * math.pi * POINT_RADIUS**3)


for _name in ("empty", "particles"):  # no geometry of their own (particles: drawn per frame)
    _register(ShapeGeometry(_name, measure=_point_measure, inertia=lambda m, d: _solid_sphere(m, POINT_RADIUS), primitives=lambda o: []))
