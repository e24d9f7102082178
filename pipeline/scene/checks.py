"""Semantic checks a schema cannot express: names and references across the scene, parent
cycles, asset files, channel names and value shapes, expressions. All problems at once."""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import Problem
from .motion_schema import KeyframeMotion, ProceduralMotion, TRANSFORM_CHANNELS
from .schema import EnvmapLight, Mesh, Scene, Texture

if TYPE_CHECKING:
    from .loader import Loc, SourceMap

# Scalar channels each kind of owner may animate besides translate/rotate/scale.
SCALAR_CHANNELS = {
    "camera": ("fov", "ortho_width"),
    "object": (),
    # each light's own emission quantity (render/build.py LIGHT_CHANNEL); a keyed value replaces it
    "point light": ("intensity",),
    "spot light": ("intensity",),
    "directional light": ("irradiance",),
    "constant light": ("radiance",),
    "envmap light": ("scale",),
}
# Channels keyed with exactly one number (lights' channels also take colours).
NUMBER_CHANNELS = ("fov", "ortho_width")


def _suggest(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    if close:
        return f"; did you mean '{close[0]}'?"
    return f"; defined: {', '.join(options)}" if options else "; none are defined"




def semantic_problems(scene: Scene, base_dir: Path, source: "SourceMap") -> list[Problem]:
    problems: list[Problem] = []

    def add(loc: "Loc", message: str) -> None:
        problems.append(source.problem(loc, message))

    # names: objects and lights share one namespace (parents and springs refer to them)
    names: dict[str, "Loc"] = {}
    for kind, items in (("objects", scene.objects), ("lights", scene.lights)):
        for i, item in enumerate(items):
            name = getattr(item, "name", None)
            if name is None:
                continue
            if name in names:
                add((kind, i, "name"), f"duplicate name '{name}' (first used at {_path(names[name])})")
            else:
                names[name] = (kind, i, "name")
    materials: dict[str, int] = {}
    for i, mat in enumerate(scene.materials):
        if mat.name in materials:
            add(("materials", i, "name"), f"duplicate material name '{mat.name}'")
        materials.setdefault(mat.name, i)

    # references
    for i, obj in enumerate(scene.objects):
        if obj.material is not None and obj.material not in materials:
            add(("objects", i, "material"), f"unknown material '{obj.material}'" + _suggest(obj.material, list(materials)))
    parents: dict[str, str] = {}
    owners: list[tuple["Loc", str | None, str | None]] = [(("camera",), None, scene.camera.parent)]
    owners += [(("objects", i), o.name, o.parent) for i, o in enumerate(scene.objects)]
    owners += [(("lights", i), light.name, light.parent) for i, light in enumerate(scene.lights)]
    for loc, name, parent in owners:
        if parent is None:
            continue
        if parent not in names or names[parent][0] != "objects":
            objects = [o.name for o in scene.objects]
            add((*loc, "parent"), f"unknown parent '{parent}' (parents are objects)" + _suggest(parent, objects))
        elif name is not None:
            if parent == name:
                add((*loc, "parent"), f"'{name}' cannot be its own parent")
            parents[name] = parent
    # cycles: follow each chain; report each cycle once, at its first member in file order
    reported: set[frozenset[str]] = set()
    for i, obj in enumerate(scene.objects):
        chain = [obj.name]
        node = parents.get(obj.name)
        while node is not None and node not in chain:
            chain.append(node)
            node = parents.get(node)
        if node is not None and node != obj.name and node in chain:
            continue  # obj leads into a cycle it is not part of; reported at a member
        if node == obj.name and len(chain) > 1:
            cycle = frozenset(chain)
            if cycle not in reported:
                reported.add(cycle)
                add(("objects", i, "parent"), "parent cycle: " + " -> ".join([*chain, obj.name]))

    # dynamics bodies are simulated in world space; a parent would fight the simulation
    for i, obj in enumerate(scene.objects):
        if obj.motion.type == "dynamics" and obj.parent is not None:
            add(("objects", i, "parent"), "a dynamics body cannot have a parent (it is simulated in world space)")
    bodies = {o.name for o in scene.objects if o.motion.type == "dynamics"}
    for j, spring in enumerate(scene.dynamics.springs):
        for end in ("a", "b"):
            target = getattr(spring, end)
            if target not in bodies:
                add(("dynamics", "springs", j, end), f"spring end '{target}' is not a dynamics body" + _suggest(target, sorted(bodies)))
        if spring.a == spring.b:
            add(("dynamics", "springs", j), "a spring needs two different bodies")

    # asset files
    def check_file(loc: "Loc", rel: str) -> None:
        if not (base_dir / rel).is_file():
            add(loc, f"file not found: {rel} (relative to {base_dir})")

    for i, obj in enumerate(scene.objects):
        if isinstance(obj, Mesh):
            check_file(("objects", i, "file"), obj.file)
    for i, light in enumerate(scene.lights):
        if isinstance(light, EnvmapLight):
            check_file(("lights", i, "file"), light.file)
    for i, mat in enumerate(scene.materials):
        tex = getattr(mat, "color", None)
        if isinstance(tex, Texture):
            check_file(("materials", i, "color", "file"), tex.file)

    # motion channels
    check_channels(("camera", "motion"), scene.camera.motion, "camera", add)
    for i, obj in enumerate(scene.objects):
        check_channels(("objects", i, "motion"), obj.motion, "object", add)
    for i, light in enumerate(scene.lights):
        check_channels(("lights", i, "motion"), light.motion, f"{light.type} light", add)
    problems.extend(expression_problems(scene, source))
    return problems


def check_channels(loc: "Loc", motion: object, owner: str, add) -> None:  # type: ignore[no-untyped-def]
    allowed = (*TRANSFORM_CHANNELS, *SCALAR_CHANNELS[owner])
    if isinstance(motion, KeyframeMotion):
        for name, channel in motion.channels.items():
            cloc = (*loc, "channels", name)
            if name not in allowed:
                add(cloc, f"unknown channel '{name}' for a {owner}" + _suggest(name, list(allowed)))
                continue
            for k, key in enumerate(channel.keys):
                kloc = (*cloc, "keys", k)
                if name == "rotate":
                    if isinstance(key.value, float):
                        add((*kloc, "value"), "a rotation key's value is Euler angles [x, y, z] in degrees")
                elif key.value is None:
                    add(kloc, f"a '{name}' key needs 'value'")
                elif name == "translate" and isinstance(key.value, float):
                    add((*kloc, "value"), "a translate key needs [x, y, z] in metres")
                elif name in NUMBER_CHANNELS and not isinstance(key.value, float):
                    add((*kloc, "value"), f"'{name}' is a scalar channel; expected one number")
                if name != "rotate" and key.turns:
                    add((*kloc, "turns"), "turns applies to rotate keys only")
    if isinstance(motion, ProceduralMotion):
        for name in motion.scalars:
            if name not in SCALAR_CHANNELS[owner]:
                add((*loc, "scalars", name), f"unknown scalar channel '{name}' for a {owner}" + _suggest(name, list(SCALAR_CHANNELS[owner])))


def expression_problems(scene: Scene, source: "SourceMap") -> list[Problem]:
    """Expressions are parsed (never executed) here, so a bad one fails before the job."""
    try:
        from ..motion.expr import ExpressionError, parse_expression
    except ImportError:  # the expression evaluator is part of the motion stage
        return []
    problems: list[Problem] = []

    def check(loc: "Loc", text: str, variables: tuple[str, ...]) -> None:
        try:
            parse_expression(text, variables)
        except ExpressionError as exc:
            problems.append(source.problem(loc, str(exc)))

    blocks: list[tuple["Loc", object]] = [(("camera", "motion"), scene.camera.motion)]
    blocks += [(("objects", i, "motion"), o.motion) for i, o in enumerate(scene.objects)]
    blocks += [(("lights", i, "motion"), light.motion) for i, light in enumerate(scene.lights)]
    for loc, motion in blocks:
        if not isinstance(motion, ProceduralMotion):
            continue
        if motion.channels is not None:
            for field in ("translate", "rotate", "scale"):
                value = getattr(motion.channels, field)
                if value is None:
                    continue
                items = [value] if isinstance(value, str) else list(value)
                for j, text in enumerate(items):
                    check((*loc, "channels", field) + ((j,) if not isinstance(value, str) else ()), text, ("t",))
        for name, text in motion.scalars.items():
            check((*loc, "scalars", name), text, ("t",))
    for field in ("wind", "force_field"):
        value = getattr(scene.dynamics, field)
        for j, text in enumerate(value or ()):
            check(("dynamics", field, j), text, ("t", "x", "y", "z"))
    return problems


def _path(loc: "Loc") -> str:
    from .loader import yaml_path

    return yaml_path(loc)
