"""What each object and light of a scene is to the renderer, fixed for a job.

An object is static (in the static set, built once, its BVH never rebuilt), a rigid mover
(in the atlas, posed per path: render/world.py), a particle system (time slices, or with
`PARTICLES_IN_TRAVERSAL` each particle a sphere on its baked path in the same traversal)
or a deforming mesh (time slices: render/slices.py). A light is static, moving (a
record that is `posed_per_path`: point, spot, directional; posed per path by the
integrator) or animated in another way (an environment light: updated per frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..scene.loader import LoadedScene


# Particle systems render as time slices (render/slices.py), not in the one traversal: a
# dense spray's proxies overlap by the hundreds along a ray (each particle's proxy holds
# its whole streak, and sprays are born at one point), and the walk visits every entry
# with two traces (docs/rendering.md measures it); a particle is then drawn at the slice
# nearest each path's time.
PARTICLES_IN_TRAVERSAL = False


def moving_objects(loaded: LoadedScene) -> set[str]:
    """The names of the objects that move: their own motion or any ancestor's (one walk up
    each object's parents, memoised: linear in the number of objects)."""
    by_name = {o.name: o for o in loaded.scene.objects}
    moves: dict[str, bool] = {}

    def walk(name: str) -> bool:
        chain: list[str] = []
        node = by_name.get(name)
        result = False
        while node is not None and node.name not in moves:
            chain.append(node.name)
            if node.motion.type != "static":
                result = True
                break
            node = by_name.get(node.parent) if node.parent else None
        else:
            result = moves.get(node.name, False) if node is not None else False
        for n in chain:
            moves[n] = result
        return result

    return {name for name in by_name if walk(name)}


def _aims_at_mover(light: Any, moving: set[str]) -> bool:
    """A spot light or projector whose `look_at` names an object that moves: it turns."""
    target = getattr(light, "look_at", None)
    return isinstance(target, str) and target in moving


@dataclass(frozen=True)
class Roles:
    """The scene's objects and lights by how the renderer draws them (names in scene order;
    lights as (index in the scene's lights, light))."""

    static_names: list[str]
    mover_names: list[str]
    slice_names: list[str]  # non-rigid geometry: particle systems and deforming meshes
    moving_lights: list[tuple[int, Any]]  # posed per path by the integrator
    animated_lights: list[tuple[int, Any]]  # other lights that change: updated per frame
    particle_names: tuple[str, ...] = ()  # the particle systems among `slice_names`

    @property
    def deform_names(self) -> list[str]:
        """The deforming meshes: the non-rigid objects that are not particle systems."""
        return [n for n in self.slice_names if n not in self.particle_names]


def sort_scene(loaded: LoadedScene) -> Roles:
    """The roles of every object and light of `loaded`."""
    objects = loaded.scene.objects
    moving = moving_objects(loaded)
    # non-rigid geometry: particle systems and deforming meshes
    slice_names = [o.name for o in objects if o.visible and o.is_nonrigid]
    sliced = set(slice_names)
    static_names = [o.name for o in objects if o.name not in moving and o.name not in sliced]
    static = set(static_names)
    mover_names = [
        o.name
        for o in objects
        if o.name not in static and o.name not in sliced and o.shape != "empty" and not o.is_particles and o.visible
    ]
    # lights whose pose can change (their own motion, a moving parent, or an aim at a moving object)
    animated = [
        (i, light)
        for i, light in enumerate(loaded.scene.lights)
        if light.motion.type != "static" or (light.parent is not None and light.parent in moving) or _aims_at_mover(light, moving)
    ]
    return Roles(
        static_names=static_names,
        mover_names=mover_names,
        slice_names=slice_names,
        particle_names=tuple(o.name for o in objects if o.name in sliced and o.is_particles) if PARTICLES_IN_TRAVERSAL else (),
        moving_lights=[(i, light) for i, light in animated if light.posed_per_path],
        animated_lights=[(i, light) for i, light in animated if not light.posed_per_path],
    )
