"""Time-sliced geometry for what is not a rigid mover: deforming meshes (blend shapes,
skinning) and particle systems.

Each such object gets S small scenes, one per baked shutter sample; a camera path with
shutter fraction u sees slice round(u (S - 1)), so every sample still has its own time
(quantised to the S baked instants) and the static BVH is never touched. Per frame only
these meshes' vertex buffers change (each slice's own small BVH is rebuilt; no kernel is
recompiled while the vertex count stays within the slice's capacity). Cost: S masked
intersections per ray and group, and S small BVH builds per frame (docs/rendering.md).

Particles are octahedra (6 vertices, 8 triangles) of the system's radius; a dead or
unborn particle collapses to a point, which no ray can hit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..motion.pose import quat_rotate
from ..scene.loader import LoadedScene
from ..scene.schema import Particles
from ..variant import load_dict
from .build import mitsuba_id

if TYPE_CHECKING:
    from .stacked import StackedFrame

# unit octahedron: particles are a pixel or two wide at typical resolutions, where 8
# triangles read as a sphere and keep the per-frame BVH builds small (an icosahedron's 20
# made the 10k-particle frame ~1.8x slower)
_OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
_OCTA_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]], dtype=np.uint32)
_NV = len(_OCTA_V)


def particle_mesh(positions: np.ndarray, alive: np.ndarray, radius: float, capacity: int) -> tuple[np.ndarray, np.ndarray]:
    """World-space vertices [capacity*6, 3] and faces [capacity*8, 3] for particles."""
    n = min(len(positions), capacity)
    centres = np.zeros((capacity, 3))
    r = np.zeros(capacity)
    centres[:n] = positions[:n]
    r[:n] = np.where(alive[:n], radius, 0.0)
    verts = centres[:, None, :] + r[:, None, None] * _OCTA_V[None, :, :]
    faces = _OCTA_F[None, :, :] + (np.arange(capacity, dtype=np.uint32) * _NV)[:, None, None]
    return verts.reshape(-1, 3), faces.reshape(-1, 3)


@dataclass
class SliceGroup:
    """The S slice scenes of one deforming object or particle system."""

    name: str
    kind: str  # "particles" | "deform"
    scenes: list[Any]
    params: list[Any]
    capacity: int  # particles (or vertices for a deforming mesh)
    faces: np.ndarray
    radius: float = 0.0
    key: str = field(default="")


def build_group(mi: Any, name: str, kind: str, count: int, faces: np.ndarray, bsdf: Any, slices: int, radius: float = 0.0) -> SliceGroup:
    """S scenes, each with one mesh of `count` vertices (or particle capacity)."""
    key = mitsuba_id(name)
    scenes, params = [], []
    for _ in range(slices):
        if kind == "particles":
            verts, fcs = particle_mesh(np.zeros((0, 3)), np.zeros(0, bool), radius, count)
        else:
            verts, fcs = np.zeros((count, 3)), faces
        props = mi.Properties()
        props["bsdf"] = bsdf
        mesh = mi.Mesh(key, len(verts), len(fcs), props, False, False)
        p = mi.traverse(mesh)
        p["vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
        p["faces"] = mi.UInt32(np.asarray(fcs, np.uint32).ravel())
        p.update()
        scene = load_dict({"type": "scene", key: mesh})
        scenes.append(scene)
        params.append(mi.traverse(scene))
    return SliceGroup(name, kind, scenes, params, count, faces, radius, key)


def update_group(mi: Any, group: SliceGroup, per_slice_vertices: list[np.ndarray]) -> None:
    """Write each slice's world-space vertices (rebuilds that slice's small BVH)."""
    for params, verts in zip(group.params, per_slice_vertices):
        params[f"{group.key}.vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
        params.update()


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


class SlicedGeometry:
    """The time-sliced groups of one job (one per name, in order): built on the cold
    frame, their vertices rewritten per frame. `on_regroup` gets every group's scenes
    whenever the set of scenes changes (the integrator's `set_slices`)."""

    def __init__(self, mi: Any, loaded: LoadedScene, names: list[str], fi: StackedFrame, materials: dict[str, Any], on_regroup: Callable[[list[list[Any]]], None]) -> None:
        self._mi = mi
        self.loaded = loaded
        self._on_regroup = on_regroup
        self.groups = [self._build(name, fi, materials) for name in names]
        on_regroup([g.scenes for g in self.groups])

    def _build(self, name: str, fi: StackedFrame, materials: dict[str, Any]) -> SliceGroup:
        from .build import DEFAULT_MATERIAL

        mi = self._mi
        obj = next(o for o in self.loaded.scene.objects if o.name == name)
        material = materials.get(obj.material, DEFAULT_MATERIAL) if obj.material else DEFAULT_MATERIAL
        bsdf = load_dict(material) if isinstance(material, dict) else material
        slices = slice_count(self.loaded, fi)
        if isinstance(obj, Particles):
            n = fi.particles[name][0].shape[1] if name in fi.particles else 0
            capacity = max(64, 1 << int(np.ceil(np.log2(max(n, 1) * 1.5))))
            return build_group(mi, name, "particles", capacity, np.zeros((0, 3)), bsdf, slices, radius=obj.radius)
        from ..motion.deform import bind_mesh

        verts, faces = bind_mesh(self.loaded, obj)
        return build_group(mi, name, "deform", len(verts), np.asarray(faces, np.uint32), bsdf, slices)

    def update(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> None:
        """Each slice's geometry at its time (`slice_samples`): particles from their
        baked positions, deforming meshes from their object-space vertices posed by the
        object's own baked frame."""
        n = fi.samples
        index = slice_samples(n, slice_count(self.loaded, fi), mode, u_fixed)
        for g in self.groups:
            per_slice = []
            if g.kind == "particles":
                positions, alive = fi.particles.get(g.name, (np.zeros((n + 1, 0, 3)), np.zeros((n + 1, 0), bool)))
                if positions.shape[1] > g.capacity:  # more particles than room: grow (one recompile)
                    self._grow(g, positions.shape[1])
                    return self.update(fi, mode, u_fixed)
                for i in index:
                    per_slice.append(particle_mesh(positions[i], alive[i], g.radius, g.capacity)[0])
            else:
                t, q, s = fi.objects[g.name]
                local = fi.vertices[g.name]
                for i in index:
                    per_slice.append(quat_rotate(q[i], local[i] * s[i]) + t[i])
            update_group(self._mi, g, per_slice)

    def _grow(self, group: SliceGroup, needed: int) -> None:
        """Replace a particle group by one with room for `needed` particles (x1.5)."""
        k = self.groups.index(group)
        capacity = 1 << int(np.ceil(np.log2(needed * 1.5)))
        bsdf = group.scenes[0].shapes()[0].bsdf()
        self.groups[k] = build_group(self._mi, group.name, "particles", capacity, group.faces, bsdf, len(group.scenes), radius=group.radius)
        self._on_regroup([g.scenes for g in self.groups])
