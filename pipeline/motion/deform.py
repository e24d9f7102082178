"""Deformation: blend shapes (vertex animation between key meshes) and linear blend
skinning (bones as a frame tree), giving object-space vertices [T, V, 3].

Bind meshes: a `mesh` object's .obj/.ply vertices in file order (pipeline/meshes.py); primitive
shapes are tessellated by their entry in pipeline/geometry.py (`tessellate`; the renderer
draws deforming objects from the same bind mesh, so vertex order matches). Validation with located errors happens here, at evaluation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import AssetError, NotAMeshError, SceneError, ShapeGeometryError
from ..geometry import tessellate
from ..meshes import load_mesh
from ..scene.motion_schema import BlendShapes, JointSkin, MorphTargets, Skinning
from ..scene.schema import Mesh
from .instances import agent_mesh
from .keyframes import MODES, VectorTrack, _catmull_rom_tangents
from .pose import Pose, UnrepresentablePoseError, compose, flatten_pose, stack_poses

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene, Loc

MAX_INFLUENCES = 4


def bind_mesh(loaded: "LoadedScene", obj: Any, detail: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The undeformed mesh of an object: its .obj/.ply file, or its tessellated primitive
    (a flock: `count` copies of its agent mesh, pipeline/dynamics/flock.py)."""
    if obj.is_flock:
        verts, faces = agent_mesh(loaded, obj)
        count = obj.deform.count
        offsets = (np.arange(count) * len(verts))[:, None, None]
        return np.tile(verts, (count, 1)), (faces[None, :, :] + offsets).reshape(-1, 3)
    if isinstance(obj, Mesh):
        return load_mesh(loaded.asset(obj.file))
    return tessellate(obj, detail)


# --- blend shapes -------------------------------------------------------------------------


def blend_shapes(loaded: "LoadedScene", loc: "Loc", deform: BlendShapes, t: np.ndarray, base_count: int | None) -> np.ndarray:
    """Per-vertex interpolation between key meshes -> [T, V, 3]."""
    shapes = []
    for i, key in enumerate(deform.keys):
        if key.vertices is not None:
            shapes.append(np.asarray(key.vertices, dtype=np.float64))
        else:
            try:
                shapes.append(load_mesh(loaded.asset(key.file or ""), faces=False)[0])
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
    from .local_pose import local_pose as _local, object_base as _object_base  # the same local-pose rules as objects
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
        try:
            posed[name] = compose(posed[bone.parent], p) if bone.parent else p
            bind[name] = compose(bind[bone.parent], b0) if bone.parent else b0
        except UnrepresentablePoseError as exc:
            raise SceneError([loaded.source.problem((*loc, "bones", i, "parent"), str(exc))]) from None
    return names, stack_poses([posed[n] for n in names]), stack_poses([bind[n] for n in names])


def skin_weights(loaded: "LoadedScene", loc: "Loc", skin: Skinning, vertices: np.ndarray, bind: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(bone indices [V, 4], weights [V, 4] summing to 1) from the file or by distance."""
    names = [b.name for b in skin.bones]
    if skin.weights is None:
        heads = bind.translation[:, 0]
        ys = np.stack([bone.length * np.array([0.0, 1.0, 0.0]) for bone in skin.bones])
        from .pose import quat_rotate, stretch_matrices

        off = None if bind.stretch_offdiag is None else bind.stretch_offdiag[:, 0]
        tails = heads + quat_rotate(bind.rotation[:, 0], np.einsum("bij,bj->bi", stretch_matrices(bind.scale[:, 0], off), ys))
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
    return flatten_pose(stacked).matrices().reshape(b, t, 4, 4)


def skinning(loaded: "LoadedScene", loc: "Loc", skin: Skinning, vertices: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear blend skinning of the bind `vertices` [V, 3] by the skin's bones -> [T, V, 3]."""
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
        deform = obj.deform
        if deform is None or obj.is_flock:  # flocks: evaluate.py, from the simulation
            continue
        loc = ("objects", i, "deform")
        try:
            if isinstance(deform, BlendShapes):
                count = len(load_mesh(loaded.asset(obj.file))[0]) if isinstance(obj, Mesh) else None
                out[obj.name] = blend_shapes(loaded, loc, deform, t, count)
            elif isinstance(deform, MorphTargets):
                out[obj.name] = morph_targets(loaded, loc, deform, _file_mesh(loaded, obj)[0], t)
            elif isinstance(deform, JointSkin):
                out[obj.name] = joint_skin(loaded, loc, deform, obj.name, _file_mesh(loaded, obj)[0], t, world)
            else:
                vertices, _ = bind_mesh(loaded, obj, deform.detail)
                out[obj.name] = skinning(loaded, loc, deform, vertices, t)
        except (ValueError, OSError, ShapeGeometryError) as exc:
            raise SceneError([loaded.source.problem(loc, str(exc))]) from None
    return out


# --- morph targets and joint skins (glTF's skins and blend shapes; docs/imports.md) --------

_MESHES: dict[tuple[str, int, int, bool], tuple[np.ndarray, np.ndarray]] = {}


def _cached_mesh(path: "Any", faces: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """load_mesh, memoised per (path, size, mtime): bind and target meshes are read once
    per process, not once per evaluation. `faces=False`: positions only (targets)."""
    st = path.stat()
    key = (str(path), st.st_size, st.st_mtime_ns, faces)
    if key not in _MESHES:
        if len(_MESHES) > 256:
            _MESHES.clear()
        _MESHES[key] = load_mesh(path, faces)
    return _MESHES[key]


def _file_mesh(loaded: "LoadedScene", obj: Any) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(obj, Mesh):
        raise NotAMeshError("morph targets and joint skins deform a mesh object (shape: mesh)")
    return _cached_mesh(loaded.asset(obj.file))


def morph_weights(loaded: "LoadedScene", loc: "Loc", deform: MorphTargets, t: np.ndarray) -> np.ndarray:
    """Weights [T, K] of the targets: keyed channels by target name, else `weight`."""
    from .local_pose import local_pose as _local  # the same keyframe rules as every channel

    names = [target.name for target in deform.targets]
    weights = np.tile(np.array([target.weight for target in deform.targets]), (len(t), 1))
    if deform.animation is not None:
        unknown = [n for n in deform.animation.channels if n not in names]
        if unknown:
            raise SceneError([loaded.source.problem((*loc, "animation", "channels", unknown[0]), f"no morph target named '{unknown[0]}'; targets: {', '.join(names)}")])
        zero = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3))
        local = _local(loaded, loc, deform.animation, zero, t, {n: 1 for n in names})
        for k, n in enumerate(names):
            if n in local.scalars:
                weights[:, k] = local.scalars[n]
    return weights


def morph_targets(loaded: "LoadedScene", loc: "Loc", deform: MorphTargets, base: np.ndarray, t: np.ndarray) -> np.ndarray:
    """base + sum_k w_k(t) (target_k - base) -> [T, V, 3]."""
    deltas = np.empty((len(deform.targets), *base.shape))
    for k, target in enumerate(deform.targets):
        try:
            verts = _cached_mesh(loaded.asset(target.file), faces=False)[0]
        except (OSError, AssetError) as exc:
            raise SceneError([loaded.source.problem((*loc, "targets", k, "file"), f"cannot read morph target: {exc}")]) from None
        if verts.shape != base.shape:
            raise SceneError([loaded.source.problem((*loc, "targets", k), f"morph target has {len(verts)} vertices; the mesh has {len(base)}")])
        deltas[k] = verts - base
    w = morph_weights(loaded, loc, deform, t)
    return base[None] + np.einsum("tk,kvc->tvc", w, deltas)


_SKINS: dict[tuple[str, int, int], dict[str, np.ndarray]] = {}


def _skin_arrays(loaded: "LoadedScene", loc: "Loc", deform: JointSkin, count: int) -> dict[str, np.ndarray]:
    path = loaded.asset(deform.file)
    try:
        st = path.stat()
        key = (str(path), st.st_size, st.st_mtime_ns)
        if key not in _SKINS:
            with np.load(path, allow_pickle=False) as z:
                _SKINS[key] = {n: np.asarray(z[n]) for n in ("inverse_bind", "joint_indices", "joint_weights")}
        arrays = _SKINS[key]
    except (OSError, KeyError, ValueError) as exc:
        raise SceneError([loaded.source.problem((*loc, "file"), f"cannot read skin file: {exc}")]) from None
    ibm, idx, w = arrays["inverse_bind"], arrays["joint_indices"], arrays["joint_weights"]
    joints = len(deform.joints)
    problem = None
    if ibm.shape != (joints, 4, 4) or not np.isfinite(ibm).all():
        problem = f"inverse_bind is {ibm.shape}; expected ({joints}, 4, 4) finite"
    elif idx.shape != w.shape or idx.ndim != 2 or len(idx) != count:
        problem = f"joint_indices {idx.shape} / joint_weights {w.shape} for a mesh of {count} vertices"
    elif idx.size and (idx.min() < 0 or idx.max() >= joints):
        problem = f"a joint index is out of range for {joints} joints"
    elif not np.isfinite(w).all() or (w < 0).any() or (w.sum(axis=1) <= 0).any():
        problem = "joint weights must be finite, non-negative and positive in sum per vertex"
    if problem:
        raise SceneError([loaded.source.problem((*loc, "file"), problem)])
    return arrays


def joint_skin(loaded: "LoadedScene", loc: "Loc", deform: JointSkin, name: str, vertices: np.ndarray, t: np.ndarray, world: dict[str, Pose]) -> np.ndarray:
    """Object-space vertices [T, V, 3] of a mesh skinned to scene objects (its joints)."""
    missing = [k for k, j in enumerate(deform.joints) if j not in world]
    if missing:
        k = missing[0]
        raise SceneError([loaded.source.problem((*loc, "joints", k), f"unknown joint object '{deform.joints[k]}'")])
    arrays = _skin_arrays(loaded, loc, deform, len(vertices))
    w = arrays["joint_weights"] / arrays["joint_weights"].sum(axis=1, keepdims=True)
    idx = arrays["joint_indices"].astype(np.int64)
    # M_j(t) = object_from_world(t) world_from_joint_j(t) joint_from_bind_j
    world_from_joint = np.stack([world[j].matrices() for j in deform.joints], axis=1)  # [T, J, 4, 4]
    object_from_world = np.linalg.inv(world[name].matrices())  # [T, 4, 4]
    skin_m = object_from_world[:, None] @ world_from_joint @ arrays["inverse_bind"][None]
    if deform.morph is None:
        return linear_blend_skinning(vertices, skin_m[:, :, :3, :], idx, w)
    morphed = morph_targets(loaded, (*loc, "morph"), deform.morph, vertices, t)
    out = np.empty_like(morphed)
    for ti in range(len(t)):
        out[ti] = linear_blend_skinning(morphed[ti], skin_m[ti : ti + 1, :, :3, :], idx, w)[0]
    return out
