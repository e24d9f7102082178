"""What each object and light of a scene is to the renderer, fixed for a job.

An object is static (in the static set, built once, its BVH never rebuilt), a rigid mover
(in the atlas, posed per path: render/kernel/world.py), a particle system (each particle a
sphere on its baked path, in the same traversal as the rigid movers) or a deforming mesh
(a mover of the same traversal on its fitted rigid track, drawing residual templates:
render/translate/deforming.py). A light is static, moving (a
record that is `posed_per_path`: point, spot, directional; posed per path by the
integrator) or animated in another way (an environment light: updated per frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ...scene.loader import LoadedScene


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
    moving_lights: list[tuple[int, Any]]  # posed per path by the integrator
    animated_lights: list[tuple[int, Any]]  # other lights that change: updated per frame
    particle_names: tuple[str, ...] = ()  # particle systems: in the traversal (render/kernel/world.py)
    deforming_names: tuple[str, ...] = ()  # deforming meshes: in the traversal (render/translate/deforming.py `DeformingMeshes`)


def sort_scene(loaded: LoadedScene) -> Roles:
    """The roles of every object and light of `loaded`."""
    objects = loaded.scene.objects
    moving = moving_objects(loaded)
    # non-rigid geometry: particle systems and deforming meshes
    nonrigid = [o for o in objects if o.visible and o.is_nonrigid]
    sliced = {o.name for o in nonrigid}
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
        deforming_names=tuple(o.name for o in nonrigid if not o.is_particles),
        particle_names=tuple(o.name for o in nonrigid if o.is_particles),
        moving_lights=[(i, light) for i, light in animated if light.posed_per_path],
        animated_lights=[(i, light) for i, light in animated if not light.posed_per_path],
    )
