"""The scene's Mitsuba records at one instant of a frame: its objects' shapes, its lights
and its sensor at the frame's time (u None) or at a shutter fraction u.

The first-frame cache builds its static set and its sensor from these (render/worker/scene_cache.py),
and the scalar fallback builds whole scenes from them, one per instant
(render/translate/scalar_fallback.py).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Iterable

import numpy as np

from ...scene.lights import light_key
from ...scene.loader import LoadedScene
from ..kernel.broadphase import sphere_proxies
from .build import dressed, light_dict, mitsuba_id, object_shapes, sensor_dict, trs_matrix
from ..poses.shutter import particles_at, pose_at

if TYPE_CHECKING:
    from ..poses.stacked import StackedFrame


def add_shapes(d: dict[str, Any], loaded: LoadedScene, objects: Iterable[Any], fi: StackedFrame, materials: dict[str, Any], u: float | None = None) -> None:
    """The visible `objects`' shapes at the frame time (u None) or at shutter fraction u,
    added to the scene dictionary d."""
    for obj in objects:
        if not obj.visible or obj.is_nonrigid:  # particles and deforming meshes: `add_particles`, `add_deforming`
            continue
        t, q, s = fi.objects[obj.name]
        ot, oq = pose_at(t, q, u)
        m = trs_matrix(ot, oq, s[0])
        if obj.name in fi.stretches:  # T R S with S the full symmetric stretch at the frame time
            m = trs_matrix(ot, oq) @ rest_frame(fi, obj.name)
        for k, shape in enumerate(object_shapes(obj, loaded, m, materials)):
            d[f"{mitsuba_id(obj.name)}__{k}"] = shape


def add_particles(d: dict[str, Any], loaded: LoadedScene, fi: StackedFrame, materials: dict[str, Any], u: float | None = None) -> None:
    """Each visible particle system's live particles at the frame's time (u None) or at
    shutter fraction u, as spheres of its radius in one Mitsuba `ellipsoids` shape (the
    spheres the traversal draws, render/kernel/world.py), added to the scene dictionary d."""
    import mitsuba as mi

    for obj in loaded.scene.objects:
        if not (obj.visible and obj.is_particles) or obj.name not in fi.particles:
            continue
        positions, alive = fi.particles[obj.name]
        p, a = particles_at(positions, alive, u)
        live = np.asarray(p, dtype=float)[np.asarray(a, dtype=bool)]
        if len(live) == 0:
            continue
        spheres = np.concatenate([live, np.full((len(live), 1), float(obj.radius))], axis=1)
        data = mi.TensorXf(np.ascontiguousarray(sphere_proxies(spheres), dtype=np.float32))  # the broadphase's record layout
        d[f"{mitsuba_id(obj.name)}__particles"] = dressed({"type": "ellipsoids", "extent": 1.0, "data": data}, obj, loaded, materials)


def add_deforming(d: dict[str, Any], loaded: LoadedScene, fi: StackedFrame, materials: dict[str, Any], u: float | None = None) -> None:
    """Each visible deforming mesh at the frame's time (u None) or at shutter fraction u,
    as one built Mitsuba mesh in world space, added to the scene dictionary d: what the
    one traversal draws at that instant (render/translate/deforming.py: the fitted rigid
    track at u, the residual template of the baked row nearest u; a flock's agents each
    on its own track), for the scalar fallback's whole scenes."""
    import mitsuba as mi

    from ...motion.pose import quat_rotate
    from ..poses.shutter import across_shutter
    from .deforming import DeformingMeshes, deformed_mesh

    names = [o.name for o in loaded.scene.objects if o.visible and o.is_nonrigid and not o.is_particles]
    if not names:
        return
    meshes = DeformingMeshes(mi, loaded, names, fi, materials)
    mode = "off" if u is None else "stochastic"
    meshes.draw(fi, mode, u)
    for g in meshes.meshes:
        t, q = across_shutter(g.track[0], g.track[1], fi.samples, mode, u)  # [pieces, N, ...]: every sample the instant
        positions, normals = g.drawn[0]
        world = quat_rotate(q[:, :1], positions[None]) + t[:, :1]  # [pieces, R, 3]
        turned = None if normals is None else quat_rotate(q[:, :1], normals[None])
        pieces = len(world)
        mesh = g.mesh._replace(faces=(g.mesh.faces[None] + (np.arange(pieces) * len(positions))[:, None, None]).reshape(-1, 3),
                               uvs=None if g.mesh.uvs is None else np.tile(g.mesh.uvs, (pieces, 1)))
        d[f"{mitsuba_id(g.name)}__deforming"] = deformed_mesh(mi, f"{mitsuba_id(g.name)}__deforming", g.bsdf, mesh, world.reshape(-1, 3),
                                                             None if turned is None else turned.reshape(-1, 3), g.emitter)


def light_record(loaded: LoadedScene, index: int, light: Any, fi: StackedFrame, u: float | None = None) -> dict[str, Any]:
    """One light at the frame's time (u None) or at shutter fraction u, placed by its baked
    world_from_light frame, with its animated scalars at the frame's time."""
    key = light_key(light, index)
    pose = fi.lights.get(key)
    m = None
    if pose is not None:
        lt, lq = pose_at(pose[0], pose[1], u)
        m = trs_matrix(lt, lq, pose[2][0])
    scalars = {k: first_value(v) for k, v in fi.light_scalars.get(key, {}).items()}
    return light_dict(light, loaded, m, scalars)


def add_lights(d: dict[str, Any], loaded: LoadedScene, fi: StackedFrame, u: float | None = None, skip: frozenset[int] = frozenset()) -> None:
    """Every light (but those whose index is in `skip`) at the frame's time (u None) or at
    shutter fraction u, added to the scene dictionary d."""
    for i, light in enumerate(loaded.scene.lights):
        if i in skip:
            continue
        d[mitsuba_id(light_key(light, i))] = light_record(loaded, i, light, fi, u)


def sensor_record(loaded: LoadedScene, spp: int, fi: StackedFrame, u: float | None = None, **extra: Any) -> dict[str, Any]:
    """The camera's sensor at the frame's time (u None) or at shutter fraction u, with the
    frame's field of view and orthographic width; `extra`: sensor_dict's keywords."""
    scene = loaded.scene
    ct, cq = pose_at(fi.camera[0], fi.camera[1], u)
    settings = scene.render
    return sensor_dict(scene.camera, trs_matrix(ct, cq), float(fi.fov[0]), settings.resolution, spp, settings.filter, ortho_width=ortho_width(fi), **extra)


def ortho_width(fi: StackedFrame) -> float | None:
    """The orthographic width at the frame's time, if the camera is orthographic."""
    return None if fi.ortho_width is None else float(fi.ortho_width[0])


def rest_frame(fi: StackedFrame, name: str) -> np.ndarray:
    """[4, 4] an object's stretch at the frame time (diag(scale) or the full symmetric S),
    which the renderer applies in the object's rest frame, per frame."""
    m = np.eye(4)
    if name in fi.stretches:
        m[:3, :3] = fi.stretches[name][0]
    else:
        m[:3, :3] = np.diag(np.asarray(fi.objects[name][2][0], dtype=float))
    return m


def first_value(values: np.ndarray) -> Any:
    """The frame-time value of an animated scalar or colour channel."""
    v = np.asarray(values)[0]
    return float(v) if np.ndim(v) == 0 else tuple(float(x) for x in np.ravel(v))
