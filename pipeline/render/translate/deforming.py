"""Deforming meshes (blend shapes, skinning, flocks) in the one traversal (render/kernel/world.py).

A deforming mesh is a mover of the broadphase like any rigid one, posed at each lane's own
time by its *fitted rigid track*, and drawing one of S residual templates in the atlas
(`DeformingMeshes`). Per baked sample i the object-space vertices Y_i are fitted by a rigid
motion of the frame's own vertices X = Y_0 (`rigid_fit`: least squares, Kabsch); the track
is the object's own pose composed with that motion, and the residual W_i = R_i^T (Y_i - T_i)
is what the motion leaves. A mesh that moves rigidly (its object, or a bone that carries it
whole) has W_i = X at every sample: its blur is its rigid twin's, continuous and exact.
What the fit cannot carry (a bend, a wave) is the residual: S = `render.time_slices`
templates at the samples of `slice_samples`, and a lane at u draws the two around u with
probabilities by their distance (a dither, render/poses/kernel.py `Movers.template_of`): a
crossfade, never a gap. Per instant drawn only these templates' vertices are written into
the atlas (one BVH build); the trace sites stay the same whatever their number.

A flock is instanced: each agent is a mover of its own, its track fitted to the agent mesh
(exact: agents are rigid copies of it), and every agent draws the one template of the agent
mesh, which never changes.

A deforming mesh is drawn from its render vertices (`meshes.RenderMesh`: one per distinct
position/uv/normal corner of the file, as Mitsuba's own readers weld them), so it keeps
its texture coordinates; deformed positions map onto them through `index`. Its vertex
normals are the engine's: without file normals `vertex_normals` (Mitsuba's own scheme,
from each template's positions, so a deforming mesh at rest has its static twin's normals
to float rounding); with file normals, the file's are carried, vertex by vertex, by a
local frame (the welded mean face normal and the edge to one neighbour) from rest to the
sample (`slice_normals`: exact when nothing deforms and for any rigid turn; hard edges
stay hard), then turned into the template's frame; `face_normals: true` stays faceted.
An emissive deforming mesh wears its area emitter on every template: the sampler of the
emitters on things that move samples it in its atlas cell (render/kernel/lights.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ...meshes import RenderMesh, load_render_mesh, plain_render_mesh, vertex_normals
from ...motion.pose import matrix_to_quat, quat_mul, quat_rotate
from ...scene.loader import LoadedScene
from ...scene.schema import Mesh
from ...variant import load_dict
from ..kernel.atlas import points_sphere

if TYPE_CHECKING:
    from ..poses.stacked import StackedFrame

class RestNormals(NamedTuple):
    """A deforming mesh's file normals at rest under one scale, as `slice_normals` carries
    them: each render vertex's unit normal in its file vertex's rest frame (`local` [R, 3])
    and itself (`normals` [R, 3]); the frames' axes [V, 3], degeneracy [V] and neighbours
    [V] (`_frames`)."""

    local: np.ndarray
    normals: np.ndarray
    axes: np.ndarray
    bad: np.ndarray
    neighbour: np.ndarray


def _frame_axes(positions: np.ndarray, mesh: RenderMesh) -> np.ndarray:
    """The axis of each file vertex's carrying frame [V, 3] (`positions` [V, 3]): the unit
    area-weighted mean of the normals of the faces around it, welded by file vertex so that
    the render vertices of a uv seam or a hard edge share one frame. Not a normal anyone
    draws (those are the file's or `vertex_normals`): the direction whose turn from rest to
    a slice `slice_normals` applies to the file's normals (area-weighted: the closer
    estimate of a deformation's turn, docs/rendering.md)."""
    p = positions[mesh.index]
    f = mesh.faces
    face_n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])  # |.| = 2 area
    corners = mesh.index[f].ravel()
    weights = np.repeat(face_n, 3, axis=0)
    return _unit(np.stack([np.bincount(corners, weights[:, c], minlength=len(positions)) for c in range(3)], axis=1))


def neighbours(mesh: RenderMesh, count: int) -> np.ndarray:
    """For each of the `count` file vertices, one file vertex it shares an edge with (the
    next corner of a face it is in; itself where it is in none)."""
    out = np.arange(count)
    f = mesh.index[mesh.faces]
    out[f[:, 0]], out[f[:, 1]], out[f[:, 2]] = f[:, 1], f[:, 2], f[:, 0]
    return out


def _frames(positions: np.ndarray, axes: np.ndarray, neighbour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A frame [V, 3, 3] per file vertex (columns: the edge to its neighbour made normal to
    the axis, their cross product, the axis) and where it is degenerate (no axis, or an
    edge along it)."""
    e = positions[neighbour] - positions
    t = e - np.sum(e * axes, axis=1, keepdims=True) * axes
    length = np.linalg.norm(t, axis=1)
    t = _unit(t)
    return np.stack([t, np.cross(axes, t), axes], axis=2), (length < 1e-12) | ~np.any(axes != 0, axis=1)


def rest_normals(rest: np.ndarray, mesh: RenderMesh, scale: np.ndarray) -> RestNormals | None:
    """What `slice_normals` needs of the bind mesh under `scale`; None where the file has
    no normals (its slices' vertex normals are then `vertex_normals`)."""
    if mesh.normals is None:
        return None
    neighbour = neighbours(mesh, len(rest))
    axes = _frame_axes(rest * scale, mesh)
    frames, bad = _frames(rest * scale, axes, neighbour)
    n = _unit(mesh.normals / scale)  # a normal under a scale S is S^-1 n
    local = np.einsum("rji,rj->ri", frames[mesh.index], n)  # F_rest^T n
    return RestNormals(local, n, axes, bad, neighbour)


def slice_normals(positions: np.ndarray, rest: RestNormals, mesh: RenderMesh) -> np.ndarray:
    """Object-space normals [R, 3] of a deformed mesh (file vertices [V, 3], scaled) whose
    file has normals: each file normal carried by its vertex's frame (`_frames`),
    n' = F_slice F_rest^T n: exact for any rigid turn (twist included) and, with no
    deformation, n' = n (the static mesh's normals to float rounding); hard edges stay
    hard. Where a frame is degenerate (at rest or now) the normal takes the shortest turn
    of the frame's axis instead, and stays as it is at rest where that turn is undefined.
    `rest`: `rest_normals` under the same scale. No vertex normal is computed here: what is
    drawn is the file's, turned."""
    axes = _frame_axes(positions, mesh)
    frames, bad_now = _frames(positions, axes, rest.neighbour)
    turned = np.einsum("rij,rj->ri", frames[mesh.index], rest.local)
    bad = (rest.bad | bad_now)[mesh.index]
    if bad.any():
        turned[bad] = _shortest_turn(rest.axes[mesh.index][bad], axes[mesh.index][bad], rest.normals[bad])
    return _unit(turned)


def _shortest_turn(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v [N, 3] turned by the shortest rotation taking unit a to unit b (Rodrigues); v
    itself where a or b is zero or they are opposite."""
    c = np.sum(a * b, axis=1, keepdims=True)
    k = np.cross(a, b)
    ok = (c > -1.0 + 1e-9) & np.any(a != 0, axis=1, keepdims=True) & np.any(b != 0, axis=1, keepdims=True)
    turned = c * v + np.cross(k, v) + np.sum(k * v, axis=1, keepdims=True) / np.where(ok, 1.0 + c, 1.0) * k
    return np.where(ok, turned, v)


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def render_mesh(loaded: LoadedScene, obj: Any, count: int, faces: np.ndarray) -> tuple[RenderMesh, bool]:
    """The render vertices of a deforming object whose bind mesh has `count` vertices and
    `faces`, and whether it is drawn smooth: a mesh file's own corners (uvs, normals;
    smooth unless `face_normals`), a tessellated sphere or capsule smooth, any other
    primitive or a flock's agents faceted, without uvs."""
    from ...scene.motion_schema import Flock

    if isinstance(obj, Mesh) and not isinstance(obj.deform, Flock):
        mesh = load_render_mesh(loaded.asset(obj.file))
        if obj.face_normals:
            mesh = mesh._replace(normals=None)
        return mesh, not obj.face_normals
    return plain_render_mesh(count, faces), obj.shape in ("sphere", "capsule") and not isinstance(obj.deform, Flock)


def slice_count(loaded: LoadedScene, fi: StackedFrame) -> int:
    """S: `render.time_slices`, at most the frame's N baked samples, at least 1."""
    return max(1, min(loaded.scene.render.time_slices, fi.samples))


def slice_samples(n: int, count: int, mode: str, u_fixed: float | None) -> list[int]:
    """The stacked row each of the `count` slices shows (row 0: the frame's time, rows
    1..n: the shutter samples): slice s of S the sample nearest u = s / (S - 1); all at one
    instant for `off` and for one sub-frame at shutter fraction `u_fixed`."""
    if mode == "off":
        return [0] * count
    if u_fixed is not None:
        return [1 + int(round(u_fixed * (n - 1)))] * count
    if count == 1:
        return [0]
    return [1 + int(round(s * (n - 1) / (count - 1))) for s in range(count)]


def rigid_fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motions (R [K, 3, 3], T [K, 3]) taking points x [V, 3] closest to each of
    y [K, V, 3] in least squares (Kabsch: the SVD of the cross-covariance, its reflection
    removed): y_k ~ x R_k^T + T_k. Exact (to rounding) where y_k is a rigid motion of x."""
    cx = x.mean(axis=0)
    cy = y.mean(axis=1)
    h = np.einsum("vi,kvj->kij", x - cx, y - cy[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, 1, 2) @ np.swapaxes(u, 1, 2)))
    d = np.where(d == 0, 1.0, d)  # a reflection would turn the mesh inside out
    fix = np.broadcast_to(np.eye(3), h.shape).copy()
    fix[:, 2, 2] = d
    r = np.swapaxes(vt, 1, 2) @ fix @ np.swapaxes(u, 1, 2)
    return r, cy - np.einsum("kij,j->ki", r, cx)


@dataclass
class DeformingMesh:
    """One deforming mesh drawn in the atlas: its render vertices, material and, for the
    frame last fitted, its movers' fitted tracks, its residual vertices and what its
    templates show. `pieces`: its movers (a flock's agents; else 1)."""

    name: str
    mesh: RenderMesh
    smooth: bool
    rest: np.ndarray  # the bind mesh's file vertices [V, 3] (a flock: one agent's)
    bsdf: Any
    pieces: int = 1
    emitter: dict[str, Any] | None = None  # the area emitter every template wears
    rest_cache: dict[tuple[float, ...], Any] = field(default_factory=dict)  # scale -> `rest_normals`
    track: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 0, 3)), np.zeros((0, 0, 4)))  # world_from_template [pieces, 1+N, 3], [pieces, 1+N, 4]
    residual: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))  # W [1+N, V, 3] (file vertices)
    turn: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))  # the fit's R [1+N, 3, 3]
    sphere: np.ndarray = field(default_factory=lambda: np.zeros(4))  # holds every template it may draw (centre, radius)
    scaled: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))  # Y [1+N, V, 3]: object space, scaled
    scale: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # the object's scale [1+N, 3]
    stretched: bool = False  # under a non-uniform parent scale (a full stretch, not `scale`)
    drawn: list[tuple[np.ndarray, np.ndarray | None]] = field(default_factory=list)  # per template: render positions, normals

    @property
    def instanced(self) -> bool:
        """A flock: its agents draw one template, the agent mesh."""
        return self.pieces > 1


def deformed_mesh(mi: Any, key: str, bsdf: Any, mesh: RenderMesh, positions: np.ndarray, normals: np.ndarray | None, emitter: dict[str, Any] | None = None) -> Any:
    """A built Mitsuba mesh of a deforming mesh's render vertices at `positions` [R, 3]
    (its normals written with them where it is smooth: `update_group`), with its uvs and
    its area emitter, if any."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = load_dict(emitter)
    shape = mi.Mesh(key, len(positions), len(mesh.faces), props, normals is not None, mesh.uvs is not None)
    p = mi.traverse(shape)

    def buffer(key: str, values: np.ndarray, dtype: type) -> None:  # the buffer's own type: mi.Float, or a scalar variant's storage
        p[key] = type(p[key])(np.ascontiguousarray(values, dtype).ravel())

    buffer("vertex_positions", positions, np.float32)
    buffer("faces", mesh.faces, np.uint32)
    if normals is not None:
        buffer("vertex_normals", normals, np.float32)
    if mesh.uvs is not None:
        buffer("vertex_texcoords", mesh.uvs, np.float32)
    p.update()
    return shape


class DeformingMeshes:
    """The deforming meshes of one job drawn in the atlas (see above): their movers, each
    on a fitted track, and their templates (S per mesh, one per flock). `fit` once per
    frame, `draw` per instant drawn (a frame, or each sub-frame)."""

    def __init__(self, mi: Any, loaded: LoadedScene, names: list[str], fi: StackedFrame, materials: dict[str, Any]) -> None:
        from ...motion.deform import bind_mesh
        from ...motion.instances import agent_mesh
        from .build import emitter_dict, object_material

        self._mi = mi
        self.loaded = loaded
        self.slices = slice_count(loaded, fi)  # S (the job's N is fixed)
        self.meshes: list[DeformingMesh] = []
        for name in names:
            obj = loaded.objects_by_name[name]
            material = object_material(obj, materials)
            bsdf = load_dict(material) if isinstance(material, dict) else material
            emitter = emitter_dict(obj.emission, loaded) if obj.emission is not None else None
            if obj.is_flock:
                agent, faces = agent_mesh(loaded, obj)
                self.meshes.append(DeformingMesh(name, plain_render_mesh(len(agent), faces), False, agent, bsdf, pieces=int(obj.deform.count), emitter=emitter))
                continue
            verts, faces = bind_mesh(loaded, obj, getattr(obj.deform, "detail", 16))  # the motion stage's tessellation
            mesh, smooth = render_mesh(loaded, obj, len(verts), faces)
            self.meshes.append(DeformingMesh(name, mesh, smooth, verts, bsdf, emitter=emitter))
        self._fitted: StackedFrame | None = None

    @property
    def movers(self) -> int:
        """The movers of every mesh (a flock's agents each)."""
        return sum(g.pieces for g in self.meshes)

    def templates_of(self, g: DeformingMesh) -> int:
        """How many templates mesh g draws: S, or a flock's one."""
        return 1 if g.instanced else self.slices

    def mover_templates(self, first: int) -> np.ndarray:
        """Each mover's (first template, count) [movers, 2], the templates numbered from
        `first` in mesh order (the frame data's `mover_template`)."""
        rows, at = [], first
        for g in self.meshes:
            count = self.templates_of(g)
            rows += [(at, count)] * g.pieces
            at += count
        return np.array(rows, dtype=float).reshape(-1, 2)

    def fit(self, fi: StackedFrame) -> None:
        """Each mesh's fitted tracks, residual and bounding sphere for frame `fi` (once per
        frame: a second call with the same frame does nothing)."""
        if self._fitted is fi:
            return
        for g in self.meshes:
            t, q, s = (np.asarray(a, dtype=float) for a in fi.objects[g.name])
            local = np.asarray(fi.vertices[g.name], dtype=float)
            stretch = fi.stretches.get(g.name)  # a symmetric stretch under a non-uniform parent scale
            scaled = np.einsum("rvj,rij->rvi", local, stretch) if stretch is not None else local * s[:, None, :]
            rows = len(scaled)
            if g.instanced:  # each agent fitted to the agent mesh, every row
                r, shift = rigid_fit(g.rest, scaled.reshape(rows * g.pieces, len(g.rest), 3))
                r, shift = r.reshape(rows, g.pieces, 3, 3), shift.reshape(rows, g.pieces, 3)
                tt = t[:, None] + quat_rotate(q[:, None], shift)
                qq = quat_mul(np.broadcast_to(q[:, None], (rows, g.pieces, 4)), matrix_to_quat(r))
                g.track = (np.swapaxes(tt, 0, 1), np.swapaxes(qq, 0, 1))
                g.sphere = points_sphere(g.rest)
                continue
            r, shift = rigid_fit(scaled[0], scaled[1:])
            r = np.concatenate([np.eye(3)[None], r])
            shift = np.concatenate([np.zeros((1, 3)), shift])
            g.turn = r
            g.residual = np.einsum("rvi,rij->rvj", scaled - shift[:, None], r)  # R^T (Y - T), row by row
            g.residual[0] = scaled[0]
            g.track = ((t + quat_rotate(q, shift))[None], quat_mul(q, matrix_to_quat(r))[None])
            g.sphere = points_sphere(g.residual.reshape(-1, 3))
            g.scaled, g.scale, g.stretched = scaled, s, stretch is not None
        self._fitted = fi

    def draw(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> None:
        """What each mesh's S templates show for motion-blur `mode` (`slice_samples`): the
        residual at those rows, as render vertices, with their normals; a flock's one
        template, the agent mesh, once."""
        self.fit(fi)
        rows = slice_samples(fi.samples, self.slices, mode, u_fixed)
        for g in self.meshes:
            if g.instanced:
                g.drawn = g.drawn or [(g.rest[g.mesh.index], None)]
                continue
            drawn = []
            for i in rows:
                positions = g.residual[i][g.mesh.index]
                normals = None
                if g.smooth and g.mesh.normals is not None and not g.stretched:
                    scale = g.scale[i]
                    key = tuple(float(c) for c in scale)
                    if key not in g.rest_cache:
                        g.rest_cache.clear()
                        g.rest_cache[key] = rest_normals(g.rest, g.mesh, scale)
                    normals = slice_normals(g.scaled[i], g.rest_cache[key], g.mesh) @ g.turn[i]
                elif g.smooth:  # from the positions Mitsuba is given, as it would
                    normals = vertex_normals(positions, g.mesh.faces)
                drawn.append((positions, normals))
            g.drawn = drawn

    def changing(self) -> list[tuple[int, np.ndarray, np.ndarray | None]]:
        """The templates whose vertices change per instant (not a flock's): (template
        number from the first deforming one, render positions, normals)."""
        out, at = [], 0
        for g in self.meshes:
            if not g.instanced:
                out += [(at + s, p, n) for s, (p, n) in enumerate(g.drawn)]
            at += self.templates_of(g)
        return out

    def tracks(self, mode: str, u_fixed: float | None, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Every mover's fitted track for the frame data ([movers, N, 3], [movers, N, 4]:
        the baked samples, or one instant: `poses.shutter.across_shutter`)."""
        from ..poses.shutter import across_shutter

        t = np.concatenate([g.track[0] for g in self.meshes]) if self.meshes else np.zeros((0, n + 1, 3))
        q = np.concatenate([g.track[1] for g in self.meshes]) if self.meshes else np.zeros((0, n + 1, 4))
        return across_shutter(t, q, n, mode, u_fixed)

    def whole_tracks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every mover's track over all 1 + N rows ([movers, 1+N, 3], [movers, 1+N, 4]) and
        the sphere holding what it draws [movers, 4], for the broadphase."""
        if not self.meshes:
            return np.zeros((0, 1, 3)), np.zeros((0, 1, 4)), np.zeros((0, 4))
        return (np.concatenate([g.track[0] for g in self.meshes]), np.concatenate([g.track[1] for g in self.meshes]),
                np.concatenate([np.repeat(g.sphere[None], g.pieces, axis=0) for g in self.meshes]))

    def shapes(self) -> list[list[Any]]:
        """Each template's built mesh (per mesh, its templates in order), at what it shows
        now: for building the atlas."""
        from .build import mitsuba_id

        return [[deformed_mesh(self._mi, f"{mitsuba_id(g.name)}_{s}", g.bsdf, g.mesh, p, n, g.emitter)] for g in self.meshes for s, (p, n) in enumerate(g.drawn)]
