"""Evaluate a scene's motion at any times: every object, the camera and the lights, in
world space (docs/architecture.md, "Contract: motion evaluation").

Per thing: a local pose from its `transform:` (or camera position/look_at, light
position/direction) and its motion block (static, keyframes, procedural; dynamics come
from the simulation), then world_from_thing = world_from_parent * parent_from_thing in
the tree's order. Every step is vectorised over the T times.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import MotionError, SceneError
from ..scene.lights import light_key
from ..scene.schema import Camera
from ..scene.types import Transform
from .graph import evaluation_order
from .local_pose import broadcast, local_pose, object_base, transform_base, vec3
from .pose import Pose, UnrepresentablePoseError, compose
from .rotation import aim_quats, direction_quat, look_at_quat

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene


class SimulationRequiredError(MotionError):
    """The scene has dynamics bodies or particles but no simulation was given."""


@dataclass(frozen=True)
class SceneMotion:
    """Everything that moves, at `times` (seconds, [T]). Plain arrays: small and picklable."""

    times: np.ndarray
    objects: dict[str, Pose]  # world_from_object for every object, static ones included
    camera: Pose  # world_from_camera (Mitsuba camera space: +Z forward, +Y up, +X left)
    camera_scalars: dict[str, np.ndarray]  # "fov" [T] always; keyed "ortho_width" [T]
    lights: dict[str, Pose]  # by name, unnamed lights are light<i>
    light_scalars: dict[str, dict[str, np.ndarray]]  # intensity/radiance/irradiance [T, 3], scale [T]
    vertices: dict[str, np.ndarray] = field(default_factory=dict)  # deforming meshes, object space [T, V, 3]
    particles: dict[str, Any] = field(default_factory=dict)  # ParticleSamples by object name

    def take(self, index: slice | np.ndarray) -> "SceneMotion":
        """The same motion at a subset of the times."""
        return SceneMotion(
            times=self.times[index],
            objects={k: p.take(index) for k, p in self.objects.items()},
            camera=self.camera.take(index),
            camera_scalars={k: v[index] for k, v in self.camera_scalars.items()},
            lights={k: p.take(index) for k, p in self.lights.items()},
            light_scalars={k: {n: v[index] for n, v in d.items()} for k, d in self.light_scalars.items()},
            vertices={k: v[index] for k, v in self.vertices.items()},
            particles={k: _take_particles(v, index) for k, v in self.particles.items()},
        )


def _take_particles(samples: Any, index: slice | np.ndarray) -> Any:
    """Slice ParticleSamples (ids [n], positions [T, n, 3], alive [T, n]) along time."""
    take = getattr(samples, "take", None)
    if callable(take):
        return take(index)
    return samples._replace(positions=samples.positions[index], alive=samples.alive[index])


def has_dynamics(loaded: "LoadedScene") -> bool:
    """True when evaluation needs a simulation (dynamics bodies or particle systems)."""
    return any(o.needs_simulation for o in loaded.scene.objects)


# --- local poses --------------------------------------------------------------------------


def _camera_base(cam: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if cam.transform is not None:
        return object_base(cam)
    if cam.position is not None and isinstance(cam.look_at, str):  # aimed at an object: turned per sample
        return np.asarray(cam.position, dtype=np.float64), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3)
    if cam.position is not None and cam.look_at is not None:
        return np.asarray(cam.position, dtype=np.float64), look_at_quat(cam.position, cam.look_at, cam.up), np.ones(3)
    return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3)


class _LightFrames:
    """The frames a light record makes from its fields (scene/lights.py `LightFrames`), as
    (translation [3], rotation [4] wxyz, scale [3])."""

    def identity(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The parent's own frame."""
        return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3)

    def transformed(self, transform: Transform) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A `transform:` block."""
        return transform_base(transform)

    def at(self, position: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At `position`, unrotated."""
        return np.asarray(position, dtype=np.float64), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3)

    def aimed(self, position: Any, look_at: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At `position`, +Z towards `look_at` (up +Y, or +Z when the aim is vertical); an
        aim at an object is unrotated here and turned per sample (`aim_at_object`)."""
        if isinstance(look_at, str):
            return np.asarray(position, dtype=np.float64), np.array([1.0, 0.0, 0.0, 0.0]), np.ones(3)
        up = (0.0, 1.0, 0.0)
        d = np.subtract(look_at, position)
        if np.linalg.norm(np.cross(d, up)) < 1e-9 * max(np.linalg.norm(d), 1e-300):
            up = (0.0, 0.0, 1.0)
        return np.asarray(position, dtype=np.float64), look_at_quat(position, look_at, up), np.ones(3)

    def along(self, direction: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """+Z along `direction`, at the origin."""
        return np.zeros(3), direction_quat(direction), np.ones(3)


_LIGHT_FRAMES = _LightFrames()


def _light_scalar_bases(light: Any) -> dict[str, np.ndarray]:
    """The light's own (unkeyed) emission channel: a colour as [3], a number as [1]."""
    if light.channel_size == 3:
        return {light.channel: vec3(light.emission)}
    return {light.channel: np.array([float(light.emission)])}


# --- the whole scene ----------------------------------------------------------------------


def evaluate(loaded: "LoadedScene", times: np.ndarray, simulation: Any | None = None) -> SceneMotion:
    """World-space motion of every object, the camera and every light at `times` (seconds,
    any order and count). `simulation` (from dynamics.simulate) is required when the scene
    has dynamics bodies or particle systems; raises SimulationRequiredError otherwise."""
    scene = loaded.scene
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if t.ndim != 1:
        raise MotionError(f"times must be a 1-D array of seconds, got shape {t.shape}")
    if not np.isfinite(t).all():
        raise MotionError("times must be finite")
    if has_dynamics(loaded) and simulation is None:
        bodies = [o.name for o in scene.objects if o.needs_simulation]
        raise SimulationRequiredError(
            f"{loaded.path}: scene has dynamics ({', '.join(bodies)}); run motion.pipeline.dynamics.simulate "
            "first and pass its result as simulation="
        )
    world = _object_poses(loaded, t, simulation)
    camera, camera_scalars = _camera_motion(loaded, t, world)
    lights, light_scalars = _light_motion(loaded, t, world)
    particles: dict[str, Any] = {}
    for obj in scene.objects:
        if obj.is_particles:
            particles[obj.name] = simulation.particles(obj.name, t)  # type: ignore[union-attr]
    vertices = _vertices(loaded, t, world, simulation)
    return SceneMotion(t, world, camera, camera_scalars, lights, light_scalars, vertices, particles)


def compose_at(loaded: "LoadedScene", loc: tuple[Any, ...], t: np.ndarray, world_from_parent: Pose, parent_from_thing: Pose) -> Pose:
    """world_from_thing = world_from_parent * parent_from_thing (pose.compose); a product
    that is not finite is a SceneError at the thing's `parent`, with the time."""
    try:
        return compose(world_from_parent, parent_from_thing)
    except UnrepresentablePoseError as exc:
        when = float(t[int(exc.samples[0])])
        raise SceneError([loaded.source.problem((*loc, "parent"), f"{exc} (at t = {when:.6g} s)")]) from None


def aim_at_object(loaded: "LoadedScene", loc: tuple[Any, ...], t: np.ndarray, pose: Pose, world: dict[str, Pose], target: str, up: np.ndarray | None) -> Pose:
    """`pose` turned at every sample so local +Z points from its world position at the
    world origin of object `target` at that time (its parents, keys and simulation
    included), +Y towards `up` (None: +Y, or +Z where the aim is vertical, as a fixed aim).
    A thing that reaches its target is a SceneError at its `look_at`."""
    if target not in world:
        raise SceneError([loaded.source.problem((*loc, "look_at"), f"unknown object '{target}' (look_at names an object)")])
    goal = world[target].translation
    d = goal - pose.translation
    dist = np.linalg.norm(d, axis=-1)
    if (dist <= 1e-12 * np.maximum(np.abs(goal).max(axis=-1), 1.0)).any():
        k = int(np.argmax(dist <= 1e-12 * np.maximum(np.abs(goal).max(axis=-1), 1.0)))
        raise SceneError([loaded.source.problem((*loc, "look_at"), f"the aim reaches '{target}' at t = {t[k]:.6g} s: nothing to look at")])
    if up is None:
        vertical = np.linalg.norm(np.cross(d, [0.0, 1.0, 0.0]), axis=-1) < 1e-9 * dist
        ups = np.where(vertical[:, None], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
    else:
        ups = np.broadcast_to(up, d.shape)
    return pose._replace(rotation=aim_quats(pose.translation, goal, ups))


def _object_poses(loaded: "LoadedScene", t: np.ndarray, simulation: Any | None) -> dict[str, Pose]:
    """Every object's world pose at `t`, parents first: simulated bodies from
    `simulation`, planned paths (motion/plan.py), keyed or procedural motion under the
    parent; then the IK chains (motion/ik.py) over the keyed poses."""
    scene = loaded.scene
    sampled = simulation.sample(t) if simulation is not None and any(o.motion.type == "dynamics" for o in scene.objects) else {}

    index = {o.name: i for i, o in enumerate(scene.objects)}
    world: dict[str, Pose] = {}
    local_poses: dict[str, Pose] = {}  # parent_from_object, for IK (motion/ik.py)
    for name in evaluation_order({o.name: o.parent for o in scene.objects}):
        i = index[name]
        obj = scene.objects[i]
        if obj.motion.type == "dynamics":
            if name not in sampled:
                raise MotionError(f"the simulation has no samples for dynamics body '{name}'")
            pose = sampled[name]
            world[name] = Pose(*(None if a is None else np.asarray(a, dtype=np.float64) for a in pose))
            continue
        if obj.motion.type == "plan":  # planned path (motion/plan.py); its follower is simulated
            from . import plan

            if obj.motion.follower is not None:
                world[name] = plan.follower_pose(loaded, i, simulation.follower(name), t)  # type: ignore[union-attr]
            else:
                world[name] = plan.kinematic_pose(loaded, i, t)
            continue
        local = local_pose(loaded, ("objects", i), obj.motion, object_base(obj), t, {})
        pose = Pose(local.translation, local.rotation, local.scale)
        local_poses[name] = pose
        world[name] = compose_at(loaded, ("objects", i), t, world[obj.parent], pose) if obj.parent is not None else pose
    if scene.ik:  # after the chains' keyed poses, before their children's world poses are final
        from .ik import apply_ik

        apply_ik(loaded, t, world, local_poses)
    return world


def _camera_motion(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose]) -> tuple[Pose, dict[str, np.ndarray]]:
    """The camera's world pose at `t` (under its parent) and its animated scalars (fov,
    ortho_width)."""
    cam = loaded.scene.camera
    count = len(t)
    local = local_pose(loaded, ("camera",), cam.motion, _camera_base(cam), t, {"fov": 1, "ortho_width": 1})
    camera = Pose(local.translation, local.rotation, local.scale)
    if cam.parent is not None:
        camera = compose_at(loaded, ("camera",), t, world[cam.parent], camera)
    if isinstance(cam.look_at, str):
        camera = aim_at_object(loaded, ("camera",), t, camera, world, cam.look_at, np.asarray(cam.up, dtype=np.float64))
    camera_scalars = {"fov": np.full(count, float(cam.fov))}
    if cam.type == "orthographic":
        camera_scalars["ortho_width"] = np.full(count, float(cam.ortho_width))
    camera_scalars.update(local.scalars)
    return camera, camera_scalars


def _light_motion(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose]) -> tuple[dict[str, Pose], dict[str, dict[str, np.ndarray]]]:
    """Each light's world pose at `t` (placed by its record, under its parent) and its
    emission channel, keyed by the light key."""
    count = len(t)
    lights: dict[str, Pose] = {}
    light_scalars: dict[str, dict[str, np.ndarray]] = {}
    for i, light in enumerate(loaded.scene.lights):
        bases = _light_scalar_bases(light)
        dims = {light.channel: light.channel_size}
        local = local_pose(loaded, ("lights", i), light.motion, light.frame(_LIGHT_FRAMES), t, dims)
        pose = Pose(local.translation, local.rotation, local.scale)
        name = light_key(light, i)
        lights[name] = compose_at(loaded, ("lights", i), t, world[light.parent], pose) if light.parent is not None else pose
        target = getattr(light, "look_at", None)
        if isinstance(target, str):
            lights[name] = aim_at_object(loaded, ("lights", i), t, lights[name], world, target, None)
        scalars = {k: (np.full(count, v[0]) if v.shape == (1,) else broadcast(v, count)) for k, v in bases.items()}
        scalars.update(local.scalars)
        light_scalars[name] = scalars
    return lights, light_scalars


def _vertices(loaded: "LoadedScene", t: np.ndarray, world: dict[str, Pose], simulation: Any | None) -> dict[str, Any]:
    """World-space vertices at `t` of the deforming meshes (motion/deform.py) and of the
    flocks' agents (simulated by the dynamics stage, dynamics/flock.py)."""
    from .deform import deformed_vertices

    vertices = deformed_vertices(loaded, t, world)
    for i, obj in enumerate(loaded.scene.objects):
        if obj.is_flock:
            from .instances import object_vertices

            try:
                vertices[obj.name] = object_vertices(loaded, obj, simulation.flock(obj.name), t, world[obj.name])  # type: ignore[union-attr]
            except ValueError as exc:
                raise SceneError([loaded.source.problem(("objects", i, "deform"), str(exc))]) from None
    return vertices
