"""What a frame looks like apart from its motion: the look half of a frame's key
(docs/reruns.md).

A frame shows the scene's content (geometry, materials, lights' parameters, the camera's
lens), rendered with its settings from the files it reads, posed by its own baked motion.
The look is the first three, without names and without motion: each object, material and
light counts by its place in the scene (`o3`, `m1`, `l0`), an object's material by the
material's place; the scene's and each thing's name, its motion block, parent and
collider, the dynamics, IK, imports (counted by what they expand to), timeline and the
output's naming and metadata are left out. Motion reaches the renderer only as the
frame's baked motion, whose digest is the key's other half (identity/motion_digest.py); what
the motion blocks decide for the renderer as a whole (which objects it draws static,
as movers or as slices: render/translate/roles.py, given by the caller, which sits above this stage)
is a part of the look.

Every part has its own digest in a frame's header (`motion:look_parts`), so a rerun says
which material, object or light changed.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from ..scene.loader import LoadedScene
from .inputs import RENDERER_VERSION, content_named, render_settings
from .motion_digest import Order

# fields of an object, light or camera (at any depth) that reach the renderer only as
# baked motion or not at all
NOT_SEEN = frozenset({"name", "motion", "animation", "parent", "collider"})


def _seen(value: Any) -> Any:
    """A record's JSON dump without the fields in NOT_SEEN, at any depth."""
    if isinstance(value, dict):
        return {k: _seen(v) for k, v in value.items() if k not in NOT_SEEN}
    if isinstance(value, list):
        return [_seen(v) for v in value]
    return value


def _digest(value: Any) -> str:
    """16 hex digits of SHA-256 over canonical JSON."""
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16]


def look_parts(loaded: LoadedScene, roles: Any) -> dict[str, str]:
    """{part: digest} of everything of the scene that reaches the renderer other than
    motion: `renderer` (its version), `render` (the settings and how frames are stored),
    `camera`, `m<i>` per material, `o<i>` per object, `l<i>` per light and `roles` (the
    renderer's sorting of the scene, render/translate/roles.py `sort_scene(loaded)`); every file
    named by its bytes (`content_named`), nothing by its name."""
    scene = content_named(loaded)
    dump = scene.model_dump(mode="json")
    materials = {m["name"]: f"m{i}" for i, m in enumerate(dump["materials"])}
    objects = {o["name"]: f"o{i}" for i, o in enumerate(dump["objects"])}
    parts: dict[str, Any] = {"renderer": RENDERER_VERSION, "render": render_settings(scene), "camera": _seen(dump["camera"])}
    parts.update({f"m{i}": _seen(m) for i, m in enumerate(dump["materials"])})
    for i, o in enumerate(dump["objects"]):
        seen = _seen(o)
        if o.get("material") is not None:
            seen["material"] = materials.get(o["material"], o["material"])
        parts[f"o{i}"] = seen
    parts.update({f"l{i}": _seen(light) for i, light in enumerate(dump["lights"])})
    parts["roles"] = {
        "static": [objects[n] for n in roles.static_names],
        "movers": [objects[n] for n in roles.mover_names],
        "slices": [objects[n] for n in roles.deforming_names],
        "moving_lights": [i for i, _ in roles.moving_lights],
        "animated_lights": [i for i, _ in roles.animated_lights],
    }
    return {k: _digest(v) for k, v in sorted(parts.items())}


def look_hash(parts: dict[str, str]) -> str:
    """The look's one digest (16 hex digits) from its parts."""
    return _digest(parts)


MOVING = "moving/"  # the names of motion parts, apart from the look's parts of the same key


def part_names(loaded: LoadedScene) -> dict[str, str]:
    """What each part of a frame's key is called in this scene, for the messages of a
    rerun: look parts (`material iron`, `object box`, `light sun`, `the camera`, ...) and
    motion parts (`box`, `sun`, `the camera`, `the frame's times`) under `MOVING + <part>`."""
    scene = loaded.scene
    order = Order.of(scene)
    names = {"renderer": "the renderer's version", "render": "the render settings", "camera": "the camera", "roles": "which objects and lights move"}
    names.update({f"m{i}": f"material {m.name}" for i, m in enumerate(scene.materials)})
    names.update({f"o{i}": f"object {n}" for i, n in enumerate(order.objects)})
    names.update({f"l{i}": f"light {n}" for i, n in enumerate(order.lights)})
    names.update({f"{MOVING}o{i}": n for i, n in enumerate(order.objects)})
    names.update({f"{MOVING}l{i}": n for i, n in enumerate(order.lights)})
    names.update({f"{MOVING}camera": "the camera", f"{MOVING}timing": "the frame's times (frame rate or shutter)"})
    return names
