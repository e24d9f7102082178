"""Semantic checks a schema cannot express: names and references across the scene, parent
cycles, asset files, channel names and value shapes, expressions; and the validation
stage's limits: every asset opened and decoded, every derived quantity (frame duration,
shutter sampling, particle and simulation budgets, timeline length) and the output
pattern's confinement checked before any task starts. All problems at once."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any, Callable, Iterator

from ..errors import AssetError, Problem
from ..expr import ExpressionError, parse_expression
from ..limits import MAX_IMAGE_BYTES, MAX_MESH_BYTES
from ..timeline import MAX_FRAME_NUMBER, MAX_FRAMES, format_range
from . import checked
from .files import named_files
from .problems import closest
from .motion_schema import KeyframeMotion, ProceduralMotion, TRANSFORM_CHANNELS
from .lights import extra_environments
from .schema import LIGHT_TYPES, Particles, Scene
from .source import yaml_path

# Budgets (docs/scene-format.md, "Limits"), checked over the whole timeline before any work.
MAX_SIMULATION_STEPS = 10_000_000  # fixed steps of the dynamics stage (5.8 h of shot at 1/480 s)
MAX_PARTICLES = 1_000_000  # particles spawned by all emitters together
MAX_PARTICLE_STEPS = 1_000_000_000  # particles x simulation steps (minutes of simulation)
MAX_FLOCK_AGENT_STEPS = 50_000_000  # agents x flock steps (minutes of simulation; the example flock is 240 x 360)
MAX_PARTICLE_SAMPLES = 100_000_000  # particles x baked sample times held by one bake (2.4 GB)

if TYPE_CHECKING:
    from .source import Loc, SourceMap

# Scalar channels each kind of owner may animate besides translate/rotate/scale.
SCALAR_CHANNELS = {
    "camera": ("fov", "ortho_width"),
    "object": (),
    # each light's own emission quantity (its record's `channel`); a keyed value replaces it
    **{f"{name} light": (record.channel,) for name, record in LIGHT_TYPES.items()},
}
# Channels keyed with exactly one number (lights' channels also take colours).
NUMBER_CHANNELS = ("fov", "ortho_width")


def near_file(rel: str, base_dir: Path) -> str:
    """"; did you mean 'REL'?" naming a file in the folder of `rel` (relative to
    `base_dir`) whose name is close to the missing one's (`tex/crates.png` for
    `tex/crate.png`), written as `rel` was; else "". The folder's first 10,000 entries
    are compared."""
    import os

    name = Path(rel).name
    try:
        with os.scandir(base_dir / rel[: len(rel) - len(name)] if rel.endswith(name) else (base_dir / rel).parent) as entries:
            names = [e.name for _, e in zip(range(10_000), entries) if e.name != name and e.is_file()]
    except OSError:
        return ""
    close = closest(name, names)
    if close is None:
        return ""
    return f"; did you mean '{rel[: len(rel) - len(name)] + close if rel.endswith(name) else close}'?"


def _suggest(name: str, options: list[str]) -> str:
    close = closest(name, options)
    if close:
        return f"; did you mean '{close}'?"
    return f"; defined: {', '.join(options)}" if options else "; none are defined"




@dataclass
class _Check:
    """What every semantic check sees: the scene, where its files are, whether assets are
    opened, and `add(loc, message)` for a located problem (`problems` keeps them in order)."""

    scene: Scene
    base_dir: Path
    source: "SourceMap"
    assets: bool
    problems: list[Problem] = field(default_factory=list)

    def add(self, loc: "Loc", message: str) -> None:
        """A problem located at the YAML path `loc`."""
        self.problems.append(self.source.problem(loc, message))


def _first_names(scene: Scene) -> dict[str, "Loc"]:
    """Objects' and lights' names (one namespace: parents and springs refer to them), each
    at its first use."""
    names: dict[str, "Loc"] = {}
    for kind, items in (("objects", scene.objects), ("lights", scene.lights)):
        for i, item in enumerate(items):
            if item.name is not None:
                names.setdefault(item.name, (kind, i, "name"))
    return names


def _parents(scene: Scene) -> dict[str, str]:
    """Each named thing's parent, where the parent is an object other than itself."""
    names = _first_names(scene)
    out = {}
    for item in [*scene.objects, *scene.lights]:
        parent = item.parent
        if item.name is not None and parent is not None and parent != item.name and names.get(parent, ("",))[0] == "objects":
            out[item.name] = parent
    return out


def check_names(c: _Check) -> None:
    """No two objects or lights share a name, nor two materials."""
    names: dict[str, "Loc"] = {}
    for kind, items in (("objects", c.scene.objects), ("lights", c.scene.lights)):
        for i, item in enumerate(items):
            if item.name is None:
                continue
            if item.name in names:
                c.add((kind, i, "name"), f"duplicate name '{item.name}' (first used at {yaml_path(names[item.name])})")
            else:
                names[item.name] = (kind, i, "name")
    materials: set[str] = set()
    for i, mat in enumerate(c.scene.materials):
        if mat.name in materials:
            c.add(("materials", i, "name"), f"duplicate material name '{mat.name}'")
        materials.add(mat.name)


def check_references(c: _Check) -> None:
    """Materials and parents named exist; nothing is its own parent."""
    scene = c.scene
    materials = [m.name for m in scene.materials]
    for i, obj in enumerate(scene.objects):
        if obj.material is not None and obj.material not in materials:
            c.add(("objects", i, "material"), f"unknown material '{obj.material}'" + _suggest(obj.material, list(dict.fromkeys(materials))))
    names = _first_names(scene)
    owners: list[tuple["Loc", str | None, str | None]] = [(("camera",), None, scene.camera.parent)]
    owners += [(("objects", i), o.name, o.parent) for i, o in enumerate(scene.objects)]
    owners += [(("lights", i), light.name, light.parent) for i, light in enumerate(scene.lights)]
    for loc, name, parent in owners:
        if parent is None:
            continue
        if parent not in names or names[parent][0] != "objects":
            objects = [o.name for o in scene.objects]
            c.add((*loc, "parent"), f"unknown parent '{parent}' (parents are objects)" + _suggest(parent, objects))
        elif name is not None and parent == name:
            c.add((*loc, "parent"), f"'{name}' cannot be its own parent")


def check_parent_cycles(c: _Check) -> None:
    """No cycle of parents: each reported once, at its first member in file order."""
    parents = _parents(c.scene)
    reported: set[frozenset[str]] = set()
    for i, obj in enumerate(c.scene.objects):
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
                c.add(("objects", i, "parent"), "parent cycle: " + " -> ".join([*chain, obj.name]))


def check_world_space_motion(c: _Check) -> None:
    """Dynamics bodies and planned paths live in world space: no parent; a planned path
    moves objects only."""
    scene = c.scene
    # a parent would fight the simulation
    for i, obj in enumerate(scene.objects):
        if obj.motion.type == "dynamics" and obj.parent is not None:
            c.add(("objects", i, "parent"), "a dynamics body cannot have a parent (it is simulated in world space)")
    # planned paths are in world space on the floor plane
    for i, obj in enumerate(scene.objects):
        if obj.motion.type == "plan" and obj.parent is not None:
            c.add(("objects", i, "parent"), "an object with a planned path cannot have a parent (the path is in world space)")
    for loc, owner in [(("camera", "motion"), scene.camera)] + [(("lights", i, "motion"), light) for i, light in enumerate(scene.lights)]:
        if owner.motion.type == "plan":
            c.add((*loc, "type"), "a planned path moves objects only (parent the camera or light to a planned object)")


def check_ik(c: _Check) -> None:
    """Inverse kinematics: chains of parented objects with bones of some length; targets
    and poles that are objects outside the chain's own subtree (they are read before the
    chain is solved)."""
    objects_by_name = {o.name: o for o in c.scene.objects}
    for j, ik in enumerate(c.scene.ik):
        for k, name in enumerate(ik.chain):
            if name not in objects_by_name:
                c.add(("ik", j, "chain", k), f"unknown object '{name}'" + _suggest(name, list(objects_by_name)))
            elif k > 0 and objects_by_name[name].parent != ik.chain[k - 1]:
                c.add(("ik", j, "chain", k), f"'{name}' must be a child of '{ik.chain[k - 1]}' (a chain is a run of parents and children)")
            elif objects_by_name[name].motion.type in ("dynamics", "plan"):
                c.add(("ik", j, "chain", k), f"'{name}' has {objects_by_name[name].motion.type} motion; IK turns keyed or static joints")
            elif k > 0 and _fixed_at_parent(objects_by_name[name]):
                c.add(("ik", j, "chain", k), f"the bone {ik.chain[k - 1]} -> {name} has no length ({name} sits at {ik.chain[k - 1]}'s origin and nothing "
                                             f"moves it): IK turns bones, so each needs a length (translate {name} away from {ik.chain[k - 1]})")
        for role in ("target", "pole"):
            name = getattr(ik, role)
            if name is None:
                continue
            if name not in objects_by_name:
                c.add(("ik", j, role), f"unknown object '{name}'" + _suggest(name, list(objects_by_name)))
                continue
            node = name
            while node is not None:
                if node in ik.chain:
                    c.add(("ik", j, role), f"'{name}' moves with the chain ('{node}'); a {role} must not depend on the joints it drives")
                    break
                node = objects_by_name[node].parent if node in objects_by_name else None


def check_springs(c: _Check) -> None:
    """A spring joins two different dynamics bodies."""
    bodies = {o.name for o in c.scene.objects if o.motion.type == "dynamics"}
    for j, spring in enumerate(c.scene.dynamics.springs):
        for end in ("a", "b"):
            target = getattr(spring, end)
            if target not in bodies:
                c.add(("dynamics", "springs", j, end), f"spring end '{target}' is not a dynamics body" + _suggest(target, sorted(bodies)))
        if spring.a == spring.b:
            c.add(("dynamics", "springs", j), "a spring needs two different bodies")


def simulated_dependency(scene: Scene, index: int) -> str | None:
    """The name of what makes object `index`'s pose come from the simulation (itself or a
    parent: a dynamics body, a planned path's follower; or the target or pole of an IK
    chain it hangs from), else None."""
    objs = {o.name: o for o in scene.objects}

    def chain_of(name: str | None) -> str | None:
        while name is not None and name in objs:
            o = objs[name]
            if o.motion.type == "dynamics" or o.has_follower:
                return name
            name = o.parent
        return None

    obj = scene.objects[index]
    found = chain_of(obj.name)
    if found is not None:
        return found
    ancestors: set[str] = set()
    node: str | None = obj.name
    while node is not None and node in objs and node not in ancestors:
        ancestors.add(node)
        node = objs[node].parent
    for ik in scene.ik:
        if ancestors & set(ik.chain):
            for n in (ik.target, ik.pole):
                found = chain_of(n)
                if found is not None:
                    return found
    return None


def collider_dependency_message(name: str, source: str) -> str:
    """Why a collider that moves with the simulation is refused (validation and the
    dynamics stage say the same)."""
    via = "it is" if source == name else f"it moves with '{source}', which is"
    return (f"the collider '{name}' cannot move with the simulation: {via} simulated; a collider's motion must come from keys, "
            "expressions, a planned path without a follower, IK or parents (make it a dynamics body instead)")


def check_moving_colliders(c: _Check) -> None:
    """A collider may move (keys, expressions, plans, IK, parents), but not with the
    simulation (a dynamics body or a follower above it); a particle emitter does not move.
    The dynamics stage refuses the same (dynamics/world.py), so validation says it first."""
    objs = {o.name: o for o in c.scene.objects}
    for i, obj in enumerate(c.scene.objects):
        if obj.collider is not None and obj.motion.type != "dynamics":
            source = simulated_dependency(c.scene, i)
            if source is not None:
                c.add(("objects", i, "collider"), collider_dependency_message(obj.name, source))
        if obj.is_particles:
            node, seen = obj, set()
            while node is not None and node.name not in seen:
                seen.add(node.name)
                if node.motion.type != "static":
                    c.add(("objects", i, "motion"), f"a particle emitter must not move: '{node.name}' has {node.motion.type} motion (moving emitters are not simulated)")
                    break
                node = objs.get(node.parent) if node.parent is not None else None


def check_joints(c: _Check) -> None:
    """A joint's ends are dynamics bodies (or the world for `b`), with a did-you-mean."""
    bodies = {o.name for o in c.scene.objects if o.motion.type == "dynamics"}
    for j, joint in enumerate(c.scene.dynamics.joints):
        for end in ("a", "b"):
            target = getattr(joint, end)
            if target not in bodies and not (end == "b" and target == "world"):
                c.add(("dynamics", "joints", j, end), f"joint end '{target}' is not a dynamics body" + (" (b may be 'world')" if end == "b" else "")
                      + _suggest(target, sorted(bodies)))


def check_penalty_stability(c: _Check) -> None:
    """A penalty contact's spring is within the fixed step's stability bound
    (dynamics_schema.penalty_problems)."""
    from .dynamics_schema import penalty_problems

    for loc, message in penalty_problems(c.scene):
        c.add(loc, message)


def check_asset_files(c: _Check) -> None:
    """Every file the scene names is there, and (with `assets`) opens and decodes as the
    renderer will read it, each file once however many fields name it (its outcome is
    reported at each)."""
    scene, base_dir = c.scene, c.base_dir
    decoded: dict[tuple[Path, str], str | None] = {}

    def check_file(loc: "Loc", rel: str, kind: str, deforming: bool = False) -> None:
        if not (base_dir / rel).is_file():
            if (base_dir / rel).exists():
                c.add(loc, f"not a regular file: {rel} (relative to {base_dir})")
            else:
                c.add(loc, f"file not found: {rel} (relative to {base_dir}){near_file(rel, base_dir)}")
            return
        if not c.assets or kind in ("skin", "morph"):  # checked where they are read (motion/deform.py)
            return
        key = ((base_dir / rel).resolve(), kind + ("-render" if deforming else ""))
        if key not in decoded:
            decoded[key] = None
            most = MAX_MESH_BYTES if kind == "mesh" else MAX_IMAGE_BYTES
            if not checked.passed(key[0], key[1], most):  # else these bytes passed this check before (scene/checked.py)
                try:
                    if kind == "mesh":
                        from ..meshes import load_mesh, load_render_mesh

                        # a deforming mesh is drawn from its render vertices (uvs, normals)
                        checked.check(key[0], key[1], most, load_render_mesh if deforming else load_mesh)
                    else:
                        from ..images import check_image

                        checked.check(key[0], key[1], most, check_image)
                except AssetError as exc:
                    decoded[key] = str(exc).split(": ", 1)[-1]
        if decoded[key] is not None:
            c.add(loc, f"{kind} file {rel}: {decoded[key]}")

    for loc, rel, kind, deforming in named_files(scene):
        check_file(loc, rel, kind, deforming)


def check_environment_lights(c: _Check) -> None:
    """At most one environment light (constant or envmap): Mitsuba takes one a scene."""
    lights = c.scene.lights
    for i, first in extra_environments(lights):
        c.add(("lights", i), f"a second environment light ({lights[i].type}; the first is {yaml_path(('lights', first))}, {lights[first].type}): "
              "expected at most one environment emitter (constant or envmap) in a scene, as Mitsuba allows one")


def check_derived(c: _Check) -> None:
    """What follows from several fields together: the timeline's and the simulation's
    budgets, the output pattern (`derived_problems`)."""
    c.problems.extend(derived_problems(c.scene, c.source))


def check_motion_channels(c: _Check) -> None:
    """Each motion block keys only channels its owner has (a light its own emission)."""
    check_channels(("camera", "motion"), c.scene.camera.motion, "camera", c.add)
    for i, obj in enumerate(c.scene.objects):
        check_channels(("objects", i, "motion"), obj.motion, "object", c.add)
    for i, light in enumerate(c.scene.lights):
        check_channels(("lights", i, "motion"), light.motion, f"{light.type} light", c.add)


def check_expressions(c: _Check) -> None:
    """Procedural expressions parse, use known names and (with `assets`) evaluate finite."""
    c.problems.extend(expression_problems(c.scene, c.source, evaluate=c.assets))


def _rotating_motion(motion: object) -> str | None:
    """What in a motion block turns its owner (a keyed `rotate`, a rotating generator or
    expression), or None."""
    channels = getattr(motion, "channels", None)
    if getattr(motion, "type", None) == "keyframes":
        return "a keyed rotate channel" if channels and "rotate" in channels else None
    if getattr(motion, "type", None) != "procedural":
        return None
    for g in getattr(motion, "generators", []):
        if g.type == "turntable" or (g.type == "orbit" and g.face_center) or (g.type == "oscillate" and g.channel == "rotate") \
                or (g.type == "noise" and any(g.rotate_amplitude)):
            return f"a rotating {g.type} generator" + (" (set rotate_amplitude: [0, 0, 0])" if g.type == "noise" else "")
    return "a rotate expression" if channels is not None and channels.rotate is not None else None


def check_aims(c: _Check) -> None:
    """A `look_at` that names something names an object (did you mean ...), and the
    aimed camera or light has no rotating motion (the aim sets its rotation)."""
    scene = c.scene
    objects = [o.name for o in scene.objects]
    owners = [(("camera",), scene.camera)] + [(("lights", i), light) for i, light in enumerate(scene.lights)]
    for loc, owner in owners:
        target = getattr(owner, "look_at", None)
        if not isinstance(target, str):
            continue
        if target not in objects:
            c.add((*loc, "look_at"), f"unknown object '{target}' (look_at names an object)" + _suggest(target, objects))
            continue
        why = _rotating_motion(owner.motion)
        if why is not None:
            c.add((*loc, "motion"), f"look_at aims at '{target}', which sets the rotation; {why} would fight it (key translate only, or aim at a point)")


# The semantic checks, in the order their problems are reported (file order within each).
SEMANTIC_CHECKS: tuple[Callable[[_Check], None], ...] = (
    check_names,
    check_references,
    check_parent_cycles,
    check_world_space_motion,
    check_ik,
    check_springs,
    check_moving_colliders,
    check_joints,
    check_penalty_stability,
    check_asset_files,
    check_environment_lights,
    check_derived,
    check_motion_channels,
    check_expressions,
    check_aims,
)


def semantic_problems(scene: Scene, base_dir: Path, source: "SourceMap", assets: bool = True) -> list[Problem]:
    """Every problem a schema cannot see: each of SEMANTIC_CHECKS in turn. `assets`: also
    open and decode every mesh and image (the validation stage; a worker that reloads a
    checked scene skips it)."""
    c = _Check(scene, base_dir, source, assets)
    for check in SEMANTIC_CHECKS:
        check(c)
    return c.problems


def _fixed_at_parent(obj: object) -> bool:
    """A chain joint whose translation is zero and not animated: its bone from the parent
    has no length at any time (motion/ik.py refuses the animated case when it occurs)."""
    motion = obj.motion  # type: ignore[attr-defined]
    if any(obj.transform.translate) or motion.type not in ("static", "keyframes"):  # type: ignore[attr-defined]
        return False
    return motion.type == "static" or "translate" not in motion.channels


def output_pattern_problem(pattern: str) -> str | None:
    """Why an output filename pattern could write outside the output folder, or None.

    A pattern may name sub-folders inside the output folder (`shots/{name}.####.exr`),
    never an absolute path, a drive, `..`, or an empty or hidden (`.`) component."""
    if "\x00" in pattern or "\\" in pattern:
        return "the pattern must not contain NUL or backslash characters"
    if pattern.startswith("/") or re.match(r"^[A-Za-z]:", pattern):
        return "an absolute path; a pattern is relative to the output folder (sub-folders inside it are fine)"
    parts = PurePosixPath(pattern).parts
    if any(part == ".." for part in pattern.split("/")):
        return "'..' would leave the output folder; a pattern may name sub-folders inside it, never leave it"
    if any(part in ("", ".") for part in pattern.split("/")) or not parts:
        return "empty or '.' path components are not allowed"
    if parts[-1].startswith("."):
        return "hidden file names (starting with '.') are reserved for temporary files"
    return None


def derived_problems(scene: Scene, source: "SourceMap") -> list[Problem]:
    """Quantities that follow from several fields together and would fail (or never end)
    only once work starts: timeline length, frame and shutter times as float64, particle
    and simulation budgets, the output pattern. Each is checked over the whole timeline."""
    problems: list[Problem] = []

    def add(loc: "Loc", message: str) -> None:
        problems.append(source.problem(loc, message))

    tl = scene.timeline
    for end in ("first", "last"):
        if abs(getattr(tl, end)) > MAX_FRAME_NUMBER:
            add(("timeline", end), f"frame numbers are limited to +-{MAX_FRAME_NUMBER} (got {getattr(tl, end)})")
    if problems:
        return problems
    count = tl.last - tl.first + 1
    if count > MAX_FRAMES:
        add(("timeline", "last"), f"the timeline has {count} frames; the limit is {MAX_FRAMES}")
        return problems

    # frame and shutter times as the motion stage sees them (float64 seconds): the shutter
    # interval must be longer than zero and its samples distinct at the timeline's ends
    timeline = tl.timeline()
    angle = Fraction(scene.camera.shutter.angle)
    n = scene.render.shutter_samples
    for frame in (tl.first, tl.last):
        t_open, t_close = timeline.shutter(frame, angle, scene.camera.shutter.position)
        samples = [float(t_open + (t_close - t_open) * k / (n - 1)) for k in range(n)]
        if not all(math.isfinite(x) for x in samples) or any(b <= a for a, b in zip(samples, samples[1:])):
            add(
                ("camera", "shutter", "angle"),
                f"frame {frame}: a shutter of {float(t_close - t_open):.3g} s at t = {float(timeline.seconds(frame)):.6g} s "
                f"cannot hold {n} distinct sample times in float64 (raise the shutter angle or lower render.shutter_samples)",
            )
            break

    # simulation and particle budgets over the span the dynamics stage would simulate: from
    # the first frame's shutter open (the dynamics clock, bake.simulation_range)
    t_lo = float(timeline.shutter(tl.first, angle, scene.camera.shutter.position)[0])
    t_hi = float(timeline.shutter(tl.last, angle, scene.camera.shutter.position)[1])
    span = max(0.0, t_hi - t_lo)
    clock_end = t_hi - float(timeline.seconds(tl.first))  # the last shutter close on the dynamics clock
    dynamic = [i for i, o in enumerate(scene.objects) if o.motion.type == "dynamics" or o.is_particles]
    steps = math.ceil(span / scene.dynamics.step) if dynamic else 0
    if steps > MAX_SIMULATION_STEPS:
        add(("dynamics", "step"), f"simulating {span:.6g} s at a step of {scene.dynamics.step:g} s takes {steps} steps; the limit is {MAX_SIMULATION_STEPS}")
    total = 0
    for i, obj in enumerate(scene.objects):
        if not obj.is_particles:
            continue
        spawned = particle_count(obj.emitter, clock_end)
        total += spawned
        if total > MAX_PARTICLES:
            add(("objects", i, "emitter"), f"emitters spawn {total} particles up to t = {t_hi:.6g} s (rate x emission time, capped by max_count); the limit is {MAX_PARTICLES}")
            break
        if total * max(steps, 1) > MAX_PARTICLE_STEPS:
            add(("objects", i, "emitter"), f"{total} particles x {steps} simulation steps is over the budget of {MAX_PARTICLE_STEPS} particle-steps")
            break

    for i, obj in enumerate(scene.objects):
        if obj.is_flock:
            flock = obj.deform
            agent_steps = flock.count * math.ceil(max(0.0, clock_end - flock.start) / flock.step)
            if agent_steps > MAX_FLOCK_AGENT_STEPS:
                add(("objects", i, "deform", "count"), f"{flock.count} agents x {agent_steps // flock.count} steps of {flock.step:g} s is over the budget of "
                                                       f"{MAX_FLOCK_AGENT_STEPS} agent-steps (fewer agents, a larger step or a shorter shot)")

    reason = output_pattern_problem(scene.output.filename)
    if reason is not None:
        add(("output", "filename"), f"output pattern {scene.output.filename!r}: {reason}")
    return problems


def particle_count(emitter: object, t_end: float) -> int:
    """Particles an emitter spawns before t_end (as dynamics.particles.emit counts them),
    computed without overflow for any rate."""
    e = emitter
    stop = t_end if e.stop is None else min(e.stop, t_end)  # type: ignore[attr-defined]
    if stop < e.start:  # type: ignore[attr-defined]
        return 0
    expected = (stop - e.start) * e.rate  # type: ignore[attr-defined]
    if not math.isfinite(expected) or expected >= e.max_count:  # type: ignore[attr-defined]
        return int(e.max_count)  # type: ignore[attr-defined]
    return min(int(e.max_count), int(math.floor(expected)) + 1)  # type: ignore[attr-defined]


def bake_budget_problems(scene: Scene, source: "SourceMap", frames: int) -> list[Problem]:
    """What a bake of `frames` frames would hold: particle positions at every frame time
    and shutter sample (float64). Checked with the selection, before baking."""
    samples = frames * (scene.render.shutter_samples + 1)
    timeline = scene.timeline.timeline()
    t_hi = float(timeline.seconds(scene.timeline.last)) + float(timeline.frame_duration)
    problems = []
    for i, obj in enumerate(scene.objects):
        if isinstance(obj, Particles):
            held = particle_count(obj.emitter, t_hi) * samples
            if held > MAX_PARTICLE_SAMPLES:
                problems.append(
                    source.problem(
                        ("objects", i, "emitter"),
                        f"baking {frames} frames x {scene.render.shutter_samples + 1} times would hold {held} particle positions; "
                        f"the limit is {MAX_PARTICLE_SAMPLES} (render fewer frames per job: --frames or --shard)",
                    )
                )
    return problems


def check_channels(loc: "Loc", motion: object, owner: str, add) -> None:  # type: ignore[no-untyped-def]
    """Channel names and key values of one motion block for its owner (camera, object, a kind of light); problems go to `add(loc, message)`."""
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


def expression_problems(scene: Scene, source: "SourceMap", evaluate: bool = True) -> list[Problem]:
    """Expressions are parsed (never executed as Python) here, so a bad one fails before
    the job; a channel of time alone is also evaluated at every frame time, and a value the
    renderer cannot hold (limits.py: float32; a radiance seen directly past what a
    half-float frame holds) is refused at the channel, with the first time it occurs.
    `evaluate` False (a worker reloading a checked scene) parses only. numpy is imported
    only when there is an expression to evaluate (a scene without one validates without it)."""
    from ..limits import SEEN_RADIANCE, beyond_float32, beyond_half

    problems: list[Problem] = []
    timeline = scene.timeline.timeline()
    count = scene.timeline.last - scene.timeline.first + 1
    half = scene.output.pixel_type == "half"

    def check(loc: "Loc", text: str, variables: tuple[str, ...]) -> None:
        try:
            expr = parse_expression(text, variables)
        except ExpressionError as exc:
            problems.append(source.problem(loc, str(exc)))
            return
        if variables != ("t",) or not evaluate:
            return  # a field of space and time (wind) is evaluated by the simulation
        import numpy as np

        # at most MAX_FRAMES frame times (a longer timeline is refused by derived_problems)
        times = np.arange(scene.timeline.first, scene.timeline.first + min(count, MAX_FRAMES), dtype=np.float64) / float(timeline.fps)
        try:
            with np.errstate(all="ignore"):
                value = np.broadcast_to(np.asarray(expr.evaluate({"t": times}), dtype=np.float64), times.shape)
        except (ArithmeticError, ValueError) as exc:  # an integer power past float64: OverflowError
            problems.append(source.problem(loc, f"expression {text!r} cannot be evaluated: {exc}"))
            return
        seen = half and loc[-1] in SEEN_RADIANCE
        bad = beyond_float32(value) | (beyond_half(value) if seen else False)
        if bad.any():
            k = int(np.argmax(bad))
            holds = "a half-float frame (65504)" if seen and np.isfinite(value[k]) and not beyond_float32(value[k]) else "the renderer's float32"
            problems.append(source.problem(loc, f"expression {text!r} is {float(value[k]):g} at frame {scene.timeline.first + k} (t = {times[k]:.6g} s): "
                                                f"beyond what {holds} holds"))

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



def _dark(value: object) -> bool:
    """A colour (one number or three) that emits nothing; a texture may emit."""
    if isinstance(value, (int, float)):
        return value == 0
    return isinstance(value, tuple) and all(v == 0 for v in value)


def scene_warnings(scene: Scene) -> list[str]:
    """What is valid but almost surely not meant: a scene with nothing in it, nothing
    visible in it, or no light (no light, no emissive object, no environment; lights and
    emission all of strength 0 and not animated) renders black frames; keys outside the
    timeline (`key_warnings`)."""
    out = []
    shown = [o for o in scene.objects if o.visible and o.shape != "empty"]
    if not scene.objects:
        out.append("the scene has no objects: its frames show only the lights' environment")
    elif not shown:
        out.append(f"none of the scene's {len(scene.objects)} objects is visible (empty shapes or visible: false): its frames show only the lights' environment")
    lit = [light for light in scene.lights if light.motion.type != "static" or not _dark(light.emission)]
    emissive = [o for o in shown if o.emission is not None and not _dark(o.emission.radiance)]
    if not lit and not emissive:
        what = "no lights" if not scene.lights else "only lights of strength 0"
        out.append(f"the scene has {what} and no emissive objects: every frame renders black")
    from .dynamics_schema import penalty_warnings

    out.extend(penalty_warnings(scene))
    return out + key_warnings(scene)


NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def numeric_range_problems(data: Any, source: "SourceMap", scene: Scene) -> list[Problem]:
    """The numeric range policy (limits.py) on the scene document as written, imports
    expanded: every number must be one the renderer's float32 holds, and with half-float
    output (output.pixel_type: half, the default) every radiance one a half holds, located
    at the field that says it. Animated, simulated, imported and baked values are checked
    once more after the bake (shot stage)."""
    from ..limits import SEEN_RADIANCE, float32_problem, half_problem

    problems: list[Problem] = []
    half = scene.output.pixel_type == "half"

    def walk(node: Any, loc: tuple, radiance: bool) -> None:
        if len(problems) >= 20:
            return
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, (*loc, k), radiance or k in SEEN_RADIANCE)
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, (*loc, i), radiance)
        elif isinstance(node, str) and NUMBER.match(node):
            walk(float(node), loc, radiance)  # YAML 1.1 reads 1e39 (no dot) as text; the schema reads it as a number
        elif isinstance(node, (int, float)) and not isinstance(node, bool):
            try:
                why = float32_problem(float(node))
            except OverflowError:  # an int past float64 (10**400)
                why = f"{str(node)[:12]}... ({len(str(node))} digits) is beyond what the renderer holds"
            if why is not None:
                problems.append(source.problem(loc, why))
            elif radiance and half and (why := half_problem(float(node))) is not None:
                problems.append(source.problem(loc, why))

    walk(data, (), False)
    return problems


def _keyed_blocks(node: Any, loc: tuple) -> Iterator[tuple[tuple, Any]]:
    """Every record of the scene with a `time_unit` (keyframe motion, blend shapes, an IK
    constraint's weight keys), with its YAML path, at any depth."""
    from pydantic import BaseModel

    if isinstance(node, BaseModel):
        if "time_unit" in type(node).model_fields:
            yield loc, node
        for name in type(node).model_fields:
            yield from _keyed_blocks(getattr(node, name), (*loc, name))
    elif isinstance(node, (list, tuple)):
        for i, v in enumerate(node):
            yield from _keyed_blocks(v, (*loc, i))
    elif isinstance(node, dict):
        for k, v in node.items():
            yield from _keyed_blocks(v, (*loc, k))


def _key_tracks(block: Any) -> Iterator[tuple[str, list[float], str, str]]:
    """Each track of keys of a keyed record: (name, key times in its own unit,
    interpolation, extrapolation); a keyframe block's channels, a blend shape's keys, an
    IK constraint's weight keys."""
    for name, ch in (getattr(block, "channels", None) or {}).items():
        yield f"channels.{name}", [k.time for k in ch.keys], ch.interpolation or block.interpolation, ch.extrapolation or block.extrapolation
    for field_name in ("keys", "weight"):
        value = getattr(block, field_name, None)
        if isinstance(value, list) and value and hasattr(value[0], "time"):
            yield field_name, [k.time for k in value], getattr(block, "interpolation", "linear"), getattr(block, "extrapolation", "hold")


# keys on each side of a span that an interpolation reads for the values inside it
REACH = {"hold": 1, "nearest": 1, "linear": 1}


def key_warnings(scene: Scene) -> list[str]:
    """Keys that the shot never sees, one line per track naming them. A key's
    time counts from frame 0 (`time_unit: frames`) or second 0, whatever the timeline's
    `first`: keys written as 0, 12, 23 in a shot of frames 1001-1024 all lie before it, and
    the shot holds the last one's value. The shot's span is the first frame's shutter open
    to the last frame's close; the keys just outside it that an interpolation reads (one
    on each side, two for a spline) shape what the shot sees and are not named."""
    tl = scene.timeline.timeline()
    shutter = scene.camera.shutter
    fps = float(tl.fps)
    start = float(tl.shutter(tl.first, shutter.angle, shutter.position)[0]) * fps  # in frames
    end = float(tl.shutter(tl.last, shutter.angle, shutter.position)[1]) * fps
    out = []
    for loc, block in _keyed_blocks(scene, ()):
        in_frames = block.time_unit == "frames"
        for track, times, interpolation, extrapolation in _key_tracks(block):
            frames = sorted(t if in_frames else t * fps for t in times)
            before = [t for t in frames if t < start - 1e-9]
            after = [t for t in frames if t > end + 1e-9]
            if len(before) == len(frames) or len(after) == len(frames):
                if extrapolation != "hold":
                    continue  # a cycle or a line carries them into the shot
                unseen, why = frames, f"all lie {'before' if before else 'after'} it: the shot holds the value of the {'last' if before else 'first'} one"
            else:
                reach = REACH.get(interpolation, 2)
                unseen = before[:-reach] + after[reach:]
                why = "the shot never reaches them"
            if not unseen:
                continue
            vals = [f"{t:g}" if in_frames else f"{t / fps:g}" for t in unseen]
            listed = ", ".join(vals[:6]) + (f" and {len(vals) - 6} more" if len(vals) > 6 else "")
            unit = ("frame" if in_frames else "second") + ("s" if len(vals) > 1 else "")
            hint = " (a key's time counts from frame 0, not from timeline.first)" if in_frames and tl.first > 0 and before else ""
            out.append(f"{yaml_path(loc)}.{track}: keys at {unit} {listed} lie outside the timeline (frames {format_range(tl.first, tl.last)}): {why}{hint}")
    return out
