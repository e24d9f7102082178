"""Deformation: blend shapes (vertex animation between key meshes) and linear blend
skinning (bones as a frame tree), giving object-space vertices [T, V, 3].

Bind meshes: a `mesh` object's .obj/.ply vertices in file order (pipeline/meshes.py); primitive cubes, cylinders
and rectangles are tessellated by `primitive_mesh` (the renderer uses the same function,
so vertex order matches). Validation with located errors happens here, at evaluation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import AssetError, SceneError
from ..meshes import load_mesh
from ..scene.motion_schema import BlendShapes, Skinning
from ..scene.schema import Cube, Cylinder, Mesh, Rectangle
from .keyframes import MODES, VectorTrack, _catmull_rom_tangents
from .pose import Pose, compose

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene, Loc

MAX_INFLUENCES = 4


def primitive_mesh(obj: Any, detail: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Object-space vertices and triangles of a cube (6 grids of detail^2 quads), a
    cylinder (open side, detail rings x 2*detail segments, along +Y, centred) or a
    rectangle (XY grid). Raises ValueError for other shapes."""
    if isinstance(obj, Mesh):
        raise ValueError("meshes come from their file")
    uv, tri = _grid_rect(detail, detail)
    if isinstance(obj, Rectangle):
        verts = np.column_stack(((uv[:, 0] - 0.5) * obj.width, (uv[:, 1] - 0.5) * obj.height, np.zeros(len(uv))))
        return verts, tri
    if isinstance(obj, Cube):
        size = np.broadcast_to(np.asarray(obj.size, dtype=np.float64), (3,))
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
    if isinstance(obj, Cylinder):
        segments = 2 * detail
        uv, tri = _grid_rect(segments, detail)
        theta = 2 * np.pi * uv[:, 0]
        verts = np.column_stack((obj.radius * np.cos(theta), (uv[:, 1] - 0.5) * obj.height, -obj.radius * np.sin(theta)))
        return verts, tri
    raise ValueError(f"deformation of a {getattr(obj, 'shape', type(obj).__name__)} is not supported; use a mesh, cube, cylinder or rectangle")


def _grid_rect(nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """An (nu+1) x (nv+1) grid on [0, 1]^2: uv [(nu+1)(nv+1), 2] and triangles [2 nu nv, 3]."""
    u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="xy")
    uv = np.stack((u.ravel(), v.ravel()), axis=1)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="xy")
    a = (j * (nu + 1) + i).ravel()
    b, c, d = a + 1, a + nu + 1, a + nu + 2
    return uv, np.concatenate((np.stack((a, b, d), 1), np.stack((a, d, c), 1)))


def bind_mesh(loaded: "LoadedScene", obj: Any, detail: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The undeformed mesh of an object: its .obj/.ply file, or its tessellated primitive."""
    if isinstance(obj, Mesh):
        return load_mesh(loaded.asset(obj.file))
    return primitive_mesh(obj, detail)


# --- blend shapes -------------------------------------------------------------------------


def blend_shapes(loaded: "LoadedScene", loc: "Loc", deform: BlendShapes, t: np.ndarray, base_count: int | None) -> np.ndarray:
    """Per-vertex interpolation between key meshes -> [T, V, 3]."""
    shapes = []
    for i, key in enumerate(deform.keys):
        if key.vertices is not None:
            shapes.append(np.asarray(key.vertices, dtype=np.float64))
        else:
            try:
                shapes.append(load_mesh(loaded.asset(key.file or ""))[0])
            except (OSError, AssetError) as exc:
                raise SceneError([loaded.source.problem((*loc, "keys", i, "file"), f"cannot read key mesh: {exc}")]) from None
    expect = base_count if base_count is not None else len(shapes[0])
    problems = [
        loaded.source.problem((*loc, "keys", i), f"key mesh has {len(s)} vertices; expected {expect} (the same topology as {'the object mesh' if base_count is not None else 'keys[0]'})")
        for i, s in enumerate(shapes)
        if len(s) != expect
    ]
    if problems:
        raise SceneError(problems)
    seconds = 1.0 if deform.time_unit == "seconds" else float(1 / loaded.scene.timeline.rate)
    times = np.array([k.time for k in deform.keys]) * seconds
    values = np.stack([s.ravel() for s in shapes])
    tangents = _catmull_rom_tangents(times, values, deform.extrapolation == "cycle")
    modes = np.full(max(len(times) - 1, 0), MODES[deform.interpolation], dtype=np.int8)
    track = VectorTrack(times, values, modes, tangents, tangents, deform.extrapolation)
    return track(t).reshape(len(t), expect, 3)


# --- skinning -----------------------------------------------------------------------------


def _segment_distance(points: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """Distance from each point [V, 3] to each segment head->tail [B, 3] -> [V, B]."""
    d = tails - heads
    rel = points[:, None, :] - heads[None, :, :]
    s = np.clip(np.sum(rel * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(rel - s[..., None] * d, axis=-1)


def normalise_weights(weights: np.ndarray, limit: int = MAX_INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """Dense weights [V, B] -> the `limit` largest per vertex: indices [V, k], weights
    [V, k] summing to 1 (k = min(limit, B)). Rows must have a positive weight."""
    k = min(limit, weights.shape[1])
    idx = np.argsort(-weights, axis=1, kind="stable")[:, :k]
    w = np.take_along_axis(weights, idx, axis=1)
    return idx, w / w.sum(axis=1, keepdims=True)


def auto_weights(vertices: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """Auto-rig by distance: w_b proportional to 1 / (d_b + eps)^4 to each bone segment."""
    d = _segment_distance(vertices, heads, tails)
    eps = 1e-3 * max(float(np.ptp(vertices, axis=0).max()), 1e-9)
    return 1.0 / (d + eps) ** 4


def bone_poses(loaded: "LoadedScene", loc: "Loc", skin: Skinning, t: np.ndarray) -> tuple[list[str], Pose, Pose]:
    """object_from_bone at times t ([B] poses stacked as [B, T, ...]) and at bind."""
    from .evaluate import _local, _object_base  # the same local-pose rules as objects
    from .graph import evaluation_order

    names = [b.name for b in skin.bones]
    problems = []
    for i, b in enumerate(skin.bones):
        if b.parent is not None and b.parent not in names:
            problems.append(loaded.source.problem((*loc, "bones", i, "parent"), f"unknown bone '{b.parent}'; bones: {', '.join(names)}"))
        if names.index(b.name) != i:
            problems.append(loaded.source.problem((*loc, "bones", i, "name"), f"duplicate bone name '{b.name}'"))
    if problems:
        raise SceneError(problems)
    index = {n: i for i, n in enumerate(names)}
    posed: dict[str, Pose] = {}
    bind: dict[str, Pose] = {}
    for name in evaluation_order({b.name: b.parent for b in skin.bones}):
        i = index[name]
        bone = skin.bones[i]
        base = _object_base(bone)
        local = _local(loaded, (*loc, "bones", i), bone.motion, base, t, {})
        p = Pose(local.translation, local.rotation, local.scale)
        b0 = Pose(*(x[None, :] for x in base))
        posed[name] = compose(posed[bone.parent], p) if bone.parent else p
        bind[name] = compose(bind[bone.parent], b0) if bone.parent else b0
    stack = lambda d: Pose(*(np.stack([getattr(d[n], f) for n in names]) for f in Pose._fields))  # noqa: E731
    return names, stack(posed), stack(bind)


def skin_weights(loaded: "LoadedScene", loc: "Loc", skin: Skinning, vertices: np.ndarray, bind: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(bone indices [V, 4], weights [V, 4] summing to 1) from the file or by distance."""
    names = [b.name for b in skin.bones]
    if skin.weights is None:
        heads = bind.translation[:, 0]
        ys = np.stack([bone.length * np.array([0.0, 1.0, 0.0]) for bone in skin.bones])
        from .pose import quat_rotate

        tails = heads + quat_rotate(bind.rotation[:, 0], ys * bind.scale[:, 0])
        return normalise_weights(auto_weights(vertices, heads, tails))
    if len(skin.weights) != len(vertices):
        raise SceneError([loaded.source.problem((*loc, "weights"), f"{len(skin.weights)} weight rows for a bind mesh of {len(vertices)} vertices")])
    dense = np.zeros((len(vertices), len(names)))
    problems = []
    for v, row in enumerate(skin.weights):
        for bone, w in row.items():
            if bone not in names:
                problems.append(loaded.source.problem((*loc, "weights", v, bone), f"unknown bone '{bone}'; bones: {', '.join(names)}"))
            else:
                dense[v, names.index(bone)] = w
        if sum(row.values()) <= 0:
            problems.append(loaded.source.problem((*loc, "weights", v), "a vertex needs a positive weight on some bone"))
    if problems:
        raise SceneError(problems[:20])
    return normalise_weights(dense)


def linear_blend_skinning(vertices: np.ndarray, skin_matrices: np.ndarray, idx: np.ndarray, w: np.ndarray) -> np.ndarray:
    """v'(t) = sum_k w_k M_{idx_k}(t) [v, 1]; skin_matrices [T, B, 3, 4] -> [T, V, 3]."""
    out = np.empty((skin_matrices.shape[0], len(vertices), 3))
    for ti in range(skin_matrices.shape[0]):  # T is the few shutter samples; V is vectorised
        blended = np.einsum("vk,vkij->vij", w, skin_matrices[ti][idx])
        out[ti] = np.einsum("vij,vj->vi", blended[:, :, :3], vertices) + blended[:, :, 3]
    return out


def _matrices(stacked: Pose) -> np.ndarray:
    """[B, T, ...] poses -> [B, T, 4, 4] matrices."""
    b, t = stacked.translation.shape[:2]
    flat = Pose(*(a.reshape(b * t, -1) for a in stacked))
    return flat.matrices().reshape(b, t, 4, 4)


def skinning(loaded: "LoadedScene", loc: "Loc", skin: Skinning, vertices: np.ndarray, t: np.ndarray) -> np.ndarray:
    names, posed, bind = bone_poses(loaded, loc, skin, t)
    idx, w = skin_weights(loaded, loc, skin, vertices, bind)
    # M_b(t) = object_from_bone(t) * bone_from_object(bind)
    pm = _matrices(posed).transpose(1, 0, 2, 3)  # [T, B, 4, 4]
    bm = _matrices(bind)[:, 0]  # [B, 4, 4]
    skin_m = pm @ np.linalg.inv(bm)[None]
    return linear_blend_skinning(vertices, skin_m[:, :, :3, :], idx, w)


def deformed_vertices(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose]) -> dict[str, np.ndarray]:
    """Object-space vertices [T, V, 3] of every object with a `deform:` block."""
    out: dict[str, np.ndarray] = {}
    for i, obj in enumerate(loaded.scene.objects):
        deform = getattr(obj, "deform", None)
        if deform is None:
            continue
        loc = ("objects", i, "deform")
        try:
            if isinstance(deform, BlendShapes):
                count = len(load_mesh(loaded.asset(obj.file))[0]) if isinstance(obj, Mesh) else None
                out[obj.name] = blend_shapes(loaded, loc, deform, t, count)
            else:
                vertices, _ = bind_mesh(loaded, obj, deform.detail)
                out[obj.name] = skinning(loaded, loc, deform, vertices, t)
        except (ValueError, OSError) as exc:
            raise SceneError([loaded.source.problem(loc, str(exc))]) from None
    return out
