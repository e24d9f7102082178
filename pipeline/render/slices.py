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
from typing import Any

import numpy as np

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
    key = name.replace(".", "_")
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
        scene = mi.load_dict({"type": "scene", key: mesh})
        scenes.append(scene)
        params.append(mi.traverse(scene))
    return SliceGroup(name, kind, scenes, params, count, faces, radius, key)


def update_group(mi: Any, group: SliceGroup, per_slice_vertices: list[np.ndarray]) -> None:
    """Write each slice's world-space vertices (rebuilds that slice's small BVH)."""
    for params, verts in zip(group.params, per_slice_vertices):
        params[f"{group.key}.vertex_positions"] = mi.Float(np.asarray(verts, np.float32).ravel())
        params.update()
