"""A flock's agents as vertices: each agent a copy of the object's agent mesh, turned to
face along its velocity, at any times (the motion stage's side of a flock).

The dynamics stage (pipeline/dynamics/flock.py) simulates the agents and records their
positions and velocities (a `FlockTrack`: `at(times) -> (x, v)`); evaluation turns the
track into object-space vertices here, like any other deforming mesh, and the renderer
draws each agent as an instance of the agent mesh on a rigid track fitted to them. The budget check runs before the simulation (dynamics calls
`check_instance_budget`), so a flock too big to draw is refused before any work.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import FlockTooLargeError, SceneError, ShapeGeometryError
from ..geometry import shape_geometry, tessellate
from ..meshes import load_mesh
from .pose import quat_conj, quat_rotate

AGENT_DETAIL = 4  # tessellation of a round agent (cylinder, capsule): 2 * 4 segments
MAX_INSTANCE_VERTICES = 4_000_000  # rendered vertices of a flock (agents x agent vertices)


def unit(v: np.ndarray) -> np.ndarray:
    """v / |v| along the last axis (a zero vector stays zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def facing_frames(v: np.ndarray, up: np.ndarray) -> np.ndarray:
    """world_from_agent rotations [..., 3, 3]: local +Z along v, local +Y towards `up`
    (columns x, y, z). A velocity along `up` keeps +Z along v with +Y from world +Z."""
    f = unit(v)
    side = np.cross(up, f)
    norm = np.linalg.norm(side, axis=-1, keepdims=True)
    alt = np.cross(np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0]), f)
    side = np.where(norm > 1e-9, side / np.maximum(norm, 1e-12), unit(alt))
    upv = np.cross(f, side)
    still = np.linalg.norm(v, axis=-1, keepdims=True) <= 1e-12
    eye = np.broadcast_to(np.eye(3), v.shape[:-1] + (3, 3))
    frames = np.stack((side, upv, f), axis=-1)
    return np.where(still[..., None], eye, frames)


def instance_vertices(track: Any, times: np.ndarray, agent: np.ndarray, up: np.ndarray) -> np.ndarray:
    """World-space vertices [T, n * V, 3] of every agent's copy of the `agent` mesh
    ([V, 3], agent space) at `times`, each turned to face along its velocity."""
    x, v = track.at(times)
    frames = facing_frames(v, up)  # [T, n, 3, 3]
    verts = np.einsum("tnij,vj->tnvi", frames, agent) + x[:, :, None, :]
    return verts.reshape(len(x), -1, 3)


def agent_mesh(loaded: Any, obj: Any) -> tuple[np.ndarray, np.ndarray]:
    """One flock agent (agent space, +Z forward): the object's mesh file or its primitive
    at the coarsest tessellation that is still solid (geometry.py: a cube at 1, a closed
    cylinder or a capsule at AGENT_DETAIL, 8 segments round), times the object's scale."""
    detail = 1 if obj.shape in ("cube", "rectangle") else AGENT_DETAIL
    verts, faces = load_mesh(loaded.asset(obj.file)) if shape_geometry(obj.shape).file_mesh else tessellate(obj, detail)
    return verts * np.asarray(obj.transform.scale, dtype=np.float64), faces


def check_instance_budget(loaded: Any, index: int) -> None:
    """A located error, before any simulation, when the flock's rendered vertices (agents x
    agent vertices) exceed MAX_INSTANCE_VERTICES or its agent shape cannot be instanced."""
    obj = loaded.scene.objects[index]
    try:
        agent, _ = agent_mesh(loaded, obj)
    except ShapeGeometryError as exc:
        raise SceneError([loaded.source.problem(("objects", index, "deform"), str(exc))]) from None
    if obj.deform.count * len(agent) > MAX_INSTANCE_VERTICES:
        raise SceneError([loaded.source.problem(("objects", index, "deform", "count"),
                         f"{obj.deform.count} agents x {len(agent)} vertices is more than {MAX_INSTANCE_VERTICES} vertices; use fewer agents or a simpler agent mesh")])


def object_vertices(loaded: Any, obj: Any, track: Any, times: np.ndarray, world: Any) -> np.ndarray:
    """Object-space vertices [T, n * V, 3] of a flock object: the agents' world vertices
    mapped through the inverse of the object's own world pose (the renderer maps them
    back), so the object's transform does not move the agents; its scale sizes the agent."""
    agent, _ = agent_mesh(loaded, obj)
    if obj.deform.count * len(agent) > MAX_INSTANCE_VERTICES:
        raise FlockTooLargeError(f"{obj.deform.count} agents x {len(agent)} vertices is more than {MAX_INSTANCE_VERTICES} vertices; use fewer agents or a simpler agent mesh")
    up = np.asarray(obj.deform.up, dtype=np.float64)
    verts = instance_vertices(track, times, agent, up / np.linalg.norm(up))
    t, q, s = (np.asarray(a, dtype=np.float64) for a in world[:3])
    local = quat_rotate(quat_conj(q)[:, None, :], verts - t[:, None, :])
    if world.stretch_offdiag is not None:  # S^-1 of the full stretch under a non-uniform parent
        return np.linalg.solve(world.stretch()[:, None, :, :], local[..., None])[..., 0]
    return local / s[:, None, :]
