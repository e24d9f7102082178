"""The scene -> world arrays of the simulation: static colliders, the rigid-body group
(mass properties from pipeline/geometry.py), the environment's forces, particle groups.

Everything here is built once before the first step and is constant during the run
(a body's state lives in its group's flat state vector, state.py)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import SceneError
from ..geometry import BOUND, BOX, SHAPES, shape_geometry
from ..scene.dynamics_schema import penalty_parameters
from ..motion.rotation import parent_from_object
from ..motion.rotation import transform_quat as quat_from_rotation
from . import forces
from .collisions import BoxCollider, Collider, MeshCollider, PlaneCollider, SphereCollider
from .particles import Spawns, ballistic
from .penalty import BodyShape, PenaltySet, box_shape, capsule_shape, cylinder_shape, mesh_shape, sphere_shape
from .shapes import ShapeSet
from .state import BodyProps, Environment, System
from .step import Group, StepContext, bodies_activate

if TYPE_CHECKING:
    from ..geometry import Measure
    from ..motion.pose import Pose
    from .joints import JointSet
    from .track import Track
    from ..scene import LoadedScene

RECORD_BUDGET = 256 * 2**20  # bytes of recorded particle states per system
COLLIDER_DETAIL = 16  # tessellation of primitive shapes that collide as a mesh (geometry.py)


def static_matrix(loaded: "LoadedScene", index: int, what: str) -> np.ndarray:
    """world_from_object of a static object (through static parents); a located error
    naming `what` it is when it or a parent moves."""
    objects = {o.name: (i, o) for i, o in enumerate(loaded.scene.objects)}
    i, obj = index, loaded.scene.objects[index]
    m = np.eye(4)
    while True:
        if obj.motion.type != "static":
            raise SceneError([loaded.source.problem(("objects", i, "motion"), f"{what} must not move: '{obj.name}' has {obj.motion.type} motion (moving emitters are not simulated)")])
        m = parent_from_object(obj.transform) @ m
        if obj.parent is None:
            return m
        i, obj = objects[obj.parent]


def _file_mesh(loaded: "LoadedScene", obj: object) -> tuple[np.ndarray, np.ndarray]:
    from ..meshes import load_mesh

    return load_mesh(loaded.asset(obj.file))  # type: ignore[attr-defined]


def moves(loaded: "LoadedScene", index: int) -> bool:
    """Whether object `index` or a parent has motion of its own, or it hangs from an IK
    chain: its pose changes over time."""
    objs = {o.name: o for o in loaded.scene.objects}
    obj = loaded.scene.objects[index]
    chains = {n for c in loaded.scene.ik for n in c.chain}
    node: str | None = obj.name
    while node is not None:
        if objs[node].motion.type != "static" or node in chains:
            return True
        node = objs[node].parent
    return False


def build_colliders(loaded: "LoadedScene", t_start: float = 0.0, step: float | None = None) -> list[Collider]:
    """The colliders of the scene (objects with `collider:` and no dynamics), in world
    space, each as its shape's collider form (geometry.py). A collider that moves (keys,
    procedural motion, a planned path, IK, a moving parent) is built at its pose at
    t_start and carries its rigid motion from there (kinematic.py), sampled on the step
    grid t_start + k step (`step`: the scene's dynamics.step)."""
    from ..scene.checks import collider_dependency_message, simulated_dependency
    from .kinematic import kinematic_world_poses, rigid_motion

    step = loaded.scene.dynamics.step if step is None else step
    out: list[Collider] = []
    for i, obj in enumerate(loaded.scene.objects):
        c = obj.collider
        if c is None or obj.motion.type == "dynamics":
            continue
        entry = shape_geometry(obj.shape)
        if entry.collider is None:
            can = [n for n, e in SHAPES.items() if e.collider is not None]
            raise SceneError([loaded.source.problem(("objects", i, "collider"), f"a {obj.shape} cannot be a collider (use {', '.join(can[:-1])} or {can[-1]})")])
        if not moves(loaded, i):
            out.append(_collider_form(loaded, obj, static_matrix(loaded, i, "a collider")))
            continue
        source = simulated_dependency(loaded.scene, i)
        if source is not None:
            raise SceneError([loaded.source.problem(("objects", i, "collider"), collider_dependency_message(obj.name, source))])

        def world_at(times: np.ndarray, name: str = obj.name) -> "Pose":
            return kinematic_world_poses(loaded, {name}, times)[name]

        def problem(t: float, i: int = i, name: str = obj.name) -> SceneError:
            return SceneError([loaded.source.problem(("objects", i, "collider"), f"the moving collider '{name}' changes its size or shape at t = {t:.6g} s "
                                                     "(a scale that is keyed or differs under a rotating parent); a collider moves rigidly: key its scale constant")])

        col = _collider_form(loaded, obj, world_at(np.array([t_start])).matrices()[0])
        col.motion = rigid_motion(world_at, problem, t_start, step)
        out.append(col)
    return out


def _collider_form(loaded: "LoadedScene", obj: object, m: np.ndarray) -> Collider:
    """The collider of object `obj` (with a `collider:` block) at world_from_object `m`."""
    c = obj.collider  # type: ignore[attr-defined]
    entry = shape_geometry(obj.shape)  # type: ignore[attr-defined]
    form = entry.collider(obj)  # type: ignore[misc]
    cols = m[:3, :3]
    norms = np.linalg.norm(cols, axis=0)
    rot = cols / norms[None, :]
    origin = m[:3, 3].copy()
    base = dict(name=obj.name, restitution=c.restitution, friction=c.friction, static_friction=c.static_friction if c.static_friction is not None else c.friction)  # type: ignore[attr-defined]
    if form.kind in ("plane", "disk"):
        normal = np.cross(cols[:, 0], cols[:, 1])
        normal /= np.linalg.norm(normal)
        if form.kind == "plane":
            return PlaneCollider(**base, point=origin, normal=normal, u=rot[:, 0], v=rot[:, 1], half_u=form.half[0] * norms[0], half_v=form.half[1] * norms[1])
        return PlaneCollider(**base, point=origin, normal=normal, u=rot[:, 0], v=rot[:, 1], disk_radius=form.radius * float(norms[:2].max()))
    if form.kind == "box":
        return BoxCollider(**base, center=origin, rotation=rot, half=form.half * norms)
    if form.kind == "sphere":
        return SphereCollider(**base, center=origin, radius=form.radius * float(norms.max()))
    # mesh: the file's, or the primitive's tessellation
    verts, tris = _file_mesh(loaded, obj) if entry.file_mesh else entry.tessellate(obj, COLLIDER_DETAIL)  # type: ignore[misc]
    world = verts @ cols.T + origin
    return MeshCollider(**base, triangles=world[tris])


def body_measure(loaded: "LoadedScene", obj: object) -> "Measure":
    """Mass-property inputs of a body's shape with its scale applied (geometry.py)."""
    entry = shape_geometry(obj.shape)  # type: ignore[attr-defined]
    mesh = _file_mesh(loaded, obj) if entry.file_mesh else None
    return entry.measure(obj, np.asarray(obj.transform.scale, dtype=np.float64), mesh)  # type: ignore[attr-defined]


def build_environment(loaded: "LoadedScene", names: list[str], x: np.ndarray | None = None) -> Environment:
    """The scene-wide forces of a group. Springs join the bodies `names` (their positions
    `x` [n, 3] give the rest length of springs that do not state one); a group without
    names (particles) has none."""
    d = loaded.scene.dynamics
    from ..expr import parse_expression

    def parse(texts: tuple[str, str, str] | None) -> tuple[object, object, object] | None:
        if texts is None:
            return None
        return tuple(parse_expression(t, ("t", "x", "y", "z")) for t in texts)  # type: ignore[return-value]

    springs = None
    if d.springs and names and x is not None:
        index = {n: i for i, n in enumerate(names)}
        a = np.array([index[s.a] for s in d.springs])
        b = np.array([index[s.b] for s in d.springs])
        given = np.array([np.nan if s.rest_length is None else s.rest_length for s in d.springs])
        initial = np.linalg.norm(x[b] - x[a], axis=1)
        springs = forces.SpringSet(
            a=a,
            b=b,
            stiffness=np.array([s.stiffness for s in d.springs]),
            damping=np.array([s.damping for s in d.springs]),
            rest=np.where(np.isnan(given), initial, given),
        )
    return Environment(
        gravity=np.asarray(d.gravity, dtype=np.float64),
        air_density=d.air_density,
        wind=parse(d.wind),
        force_field=parse(d.force_field),
        fluids=[forces.HalfSpaceFluid(f.level, f.density, f.drag_cd) for f in d.fluids],
        springs=springs,
        newtonian=None if d.newtonian_gravity is None else (d.newtonian_gravity.G, d.newtonian_gravity.softening),
    )


def shot_start(loaded: "LoadedScene") -> float:
    """The scene time (s) at which the dynamics clock reads 0: the timeline's first frame.
    Every `start`/`stop` of a dynamics block counts from there, as Blender and Houdini start
    a simulation at the scene's start frame: a shot numbered from 1001 simulates what the
    same shot numbered from 0 does (docs/dynamics.md)."""
    timeline = loaded.scene.timeline.timeline()
    return float(timeline.seconds(timeline.first))


def build_bodies(loaded: "LoadedScene", t_start: float, colliders: list[Collider] | None = None) -> tuple[Group, list[np.ndarray]] | None:
    """The group of dynamics bodies (None if the scene has none) and their scales, against
    `colliders` (default: build_colliders from t_start)."""
    epoch = shot_start(loaded)
    objs = [o for o in loaded.scene.objects if o.motion.type == "dynamics"]
    if not objs:
        return None
    n = len(objs)
    names = [o.name for o in objs]
    cols: dict[str, list[float] | list[np.ndarray]] = {k: [] for k in ("mass", "inv_mass", "radius", "radius_eq", "area", "cd", "linear", "restitution", "friction", "static_friction", "start", "inertia", "inv_inertia")}
    x, v, q, w, scales = [], [], [], [], []
    kind, half = np.full(n, BOUND, dtype=np.int64), np.zeros((n, 3))
    d = loaded.scene.dynamics
    on_penalty = np.array([(o.motion.contact or d.contact) == "penalty" for o in objs])
    contact_shapes: list[BodyShape | None] = [None] * n
    spring = np.zeros((2, n))  # penalty k (N/m), c (N s/m)
    for k_obj, o in enumerate(objs):
        m = o.motion
        entry = shape_geometry(o.shape)
        meas = body_measure(loaded, o)
        if on_penalty[k_obj]:
            contact_shapes[k_obj] = penalty_shape(loaded, o, meas)
            params = penalty_parameters(m.penalty or d.penalty, m.mass, m.restitution)
            spring[:, k_obj] = params.k, params.c
        r_eq = (3.0 * max(meas.volume, 1e-12) / (4.0 * math.pi)) ** (1.0 / 3.0)
        inertia = entry.inertia(m.mass, meas.dims)
        rigid = m.body == "rigid" and not m.pinned
        if entry.contact is not None:
            kind[k_obj], half[k_obj] = entry.contact(meas.dims)
        vals = dict(
            mass=m.mass,
            inv_mass=0.0 if m.pinned else 1.0 / m.mass,
            radius=meas.bound,
            radius_eq=r_eq,
            area=(m.drag.area if m.drag and m.drag.area else math.pi * (meas.section if meas.section is not None else r_eq) ** 2),
            cd=m.drag.cd if m.drag else 0.0,
            linear=m.drag.linear if m.drag else 0.0,
            restitution=m.restitution,
            friction=m.friction,
            static_friction=m.static_friction if m.static_friction is not None else m.friction,
            start=epoch + m.start,
            inertia=inertia,
            inv_inertia=1.0 / inertia if rigid else np.zeros(3),
        )
        for k, val in vals.items():
            cols[k].append(val)  # type: ignore[arg-type]
        x.append(o.transform.translate)
        q.append(quat_from_rotation(o.transform.rotate))
        v.append((0.0, 0.0, 0.0) if m.pinned else m.velocity)
        w.append(np.radians(m.angular_velocity) if rigid else np.zeros(3))
        scales.append(np.asarray(o.transform.scale, dtype=np.float64))
    props = BodyProps(names=names, **{k: np.asarray(val, dtype=np.float64) for k, val in cols.items()})
    x_arr = np.asarray(x, dtype=np.float64)
    env = build_environment(loaded, names, x_arr)
    system = System(props, env, rotating=True)
    system.x_ref = x_arr.copy()
    X = system.pack(x_arr, np.asarray(v, dtype=np.float64), np.asarray(q), np.asarray(w, dtype=np.float64))
    pairs = np.triu_indices(n, 1)
    colliders = build_colliders(loaded, t_start) if colliders is None else colliders
    if on_penalty.any():
        system.penalty = PenaltySet(on_penalty, spring[0], spring[1], contact_shapes, colliders, (pairs[0], pairs[1]), props.mass, props.inv_mass,
                                    props.inv_inertia, props.radius, props.friction, props.static_friction)
    group = Group(system, X, colliders, (pairs[0], pairs[1]), bodies_activate, shapes=ShapeSet(kind, half),
                  joints=build_joints(loaded, names, x_arr, np.asarray(q, dtype=np.float64)))
    return group, scales


def build_joints(loaded: "LoadedScene", names: list[str], x: np.ndarray, q: np.ndarray) -> "JointSet | None":
    """The scene's joints (None without any) between the bodies `names` at their start
    positions x [n, 3] and orientations q [n, 4]: anchors, axes and the hinge angle's
    reference direction moved into each body's frame (joints.py)."""
    from ..motion.pose import quat_to_matrix
    from .joints import KINDS, WORLD, JointSet

    specs = loaded.scene.dynamics.joints
    if not specs:
        return None
    index = {n: i for i, n in enumerate(names)}
    R = quat_to_matrix(q)
    rows: dict[str, list] = {k: [] for k in ("a", "b", "kind", "anchor_a", "anchor_b", "axis_a", "axis_b", "ref_a", "ref_b", "length", "limits", "break_force")}

    def local(body: int, v: np.ndarray, point: bool) -> np.ndarray:
        if body == WORLD:
            return v
        return R[body].T @ (v - x[body] if point else v)

    for spec in specs:
        a = index[spec.a]
        b = WORLD if spec.b == "world" else index[spec.b]
        b_centre = x[b] if b != WORLD else None
        pivot = np.asarray(spec.anchor, dtype=np.float64) if spec.anchor is not None else b_centre
        end_a = pivot if spec.type in ("pin", "hinge") else (np.asarray(spec.anchor_a, dtype=np.float64) if spec.anchor_a is not None else x[a])
        axis = np.asarray(spec.axis if spec.axis is not None else (0.0, 1.0, 0.0), dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        across = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
        across /= np.linalg.norm(across)
        rows["a"].append(a)
        rows["b"].append(b)
        rows["kind"].append(KINDS[spec.type])
        rows["anchor_a"].append(local(a, end_a, True))
        rows["anchor_b"].append(local(b, pivot, True))
        rows["axis_a"].append(local(a, axis, False))
        rows["axis_b"].append(local(b, axis, False))
        rows["ref_a"].append(local(a, across, False))
        rows["ref_b"].append(local(b, across, False))
        rows["length"].append(float(np.linalg.norm(end_a - pivot)) if spec.length is None else spec.length)
        lim = spec.limits
        rows["limits"].append((-np.inf, np.inf) if lim is None else (math.radians(lim[0]), math.radians(lim[1])))
        rows["break_force"].append(np.inf if spec.break_force is None else spec.break_force)
    arrays = {k: np.asarray(v, dtype=np.int64 if k in ("a", "b", "kind") else np.float64) for k, v in rows.items()}
    return JointSet(**arrays, alive=np.ones(len(specs), dtype=bool))


def body_colliders(group: Group, track: "Track", step: float) -> list[Collider]:
    """The rigid bodies as moving colliders for the particles (one way: a particle bounces
    off a body, the body does not feel it): each body's true box (cubes) or its bounding
    sphere, in its own frame, moved by its recorded pose (Track.interpolate at any time),
    with its own restitution and friction, sampled on the step grid of `step` s."""
    from .kinematic import ColliderMotion

    system = group.system
    p = system.props
    out: list[Collider] = []
    box = group.shapes.kind == BOX if group.shapes is not None else np.zeros(system.n, dtype=bool)
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def poses(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = times.tobytes()
        if key not in cache:  # every body's motion asks for the same window of grid times
            cache.clear()
            x, q = track.interpolate(times)
            cache[key] = (x, q)
        return cache[key]

    for i, name in enumerate(p.names):
        base = dict(name=name, restitution=float(p.restitution[i]), friction=float(p.friction[i]), static_friction=float(p.static_friction[i]))
        col: Collider
        if box[i]:
            col = BoxCollider(**base, center=np.zeros(3), rotation=np.eye(3), half=group.shapes.half[i].copy())  # type: ignore[union-attr]
        else:
            col = SphereCollider(**base, center=np.zeros(3), radius=float(p.radius[i]))

        def sample(times: np.ndarray, i: int = i) -> tuple[np.ndarray, np.ndarray]:
            x, q = poses(times)
            return q[:, i], x[:, i]

        col.motion = ColliderMotion(float(track.times[0]), step, sample)
        col.motion.outside_only = True
        out.append(col)
    return out


def penalty_shape(loaded: "LoadedScene", obj: object, meas: "Measure") -> BodyShape:
    """A penalty body's contact points and solid (penalty.py) from its shape, scale applied:
    spheres, capsules, boxes (`cube`), cylinders and meshes (their convex hull); any other
    shape is the sphere of its bounding radius."""
    shape, dims = obj.shape, meas.dims  # type: ignore[attr-defined]
    if shape == "sphere":
        return sphere_shape(dims["radius"])
    if shape == "capsule":
        return capsule_shape(dims["radius"], dims["height"])
    if shape == "cube":
        return box_shape(np.array([dims["sx"], dims["sy"], dims["sz"]]) / 2)
    if shape == "cylinder":
        return cylinder_shape(dims["radius"], dims["height"])
    if shape == "mesh":
        verts, _ = _file_mesh(loaded, obj)
        return mesh_shape(np.asarray(verts, dtype=np.float64) * np.asarray(obj.transform.scale, dtype=np.float64))  # type: ignore[attr-defined]
    return sphere_shape(meas.bound)


def emitter_group(loaded: "LoadedScene", index: int, spawns: Spawns, colliders: list[Collider], t_start: float, t_end: float, step: float) -> Group:
    """The particle group of the particle object `index`, whose emitter drew `spawns`."""
    obj = loaded.scene.objects[index]
    e = obj.emitter
    n = spawns.count
    radius = obj.radius * float(np.asarray(obj.transform.scale, dtype=np.float64).max())
    area = e.drag.area if e.drag and e.drag.area else math.pi * radius * radius
    props = BodyProps(
        names=[],
        mass=np.full(n, e.mass),
        inv_mass=np.full(n, 1.0 / e.mass),
        radius=np.full(n, radius),
        radius_eq=np.full(n, radius),
        area=np.full(n, area),
        cd=np.full(n, e.drag.cd if e.drag else 0.0),
        linear=np.full(n, e.drag.linear if e.drag else 0.0),
        restitution=np.full(n, e.restitution),
        friction=np.full(n, e.friction),
        static_friction=np.full(n, e.friction),
        start=spawns.birth,
        inertia=np.zeros((n, 3)),
        inv_inertia=np.zeros((n, 3)),
    )
    env = build_environment(loaded, [])
    system = System(props, env, rotating=False)
    return particle_group(system, spawns, colliders, t_start, t_end, step)


def particle_group(system: System, spawns: Spawns, colliders: list[Collider], t_start: float, t_end: float, step: float) -> Group:
    """A particle group: unborn particles ride their backward ballistic path, are born at
    the first step boundary after their birth time, die (freeze) at birth + lifetime."""
    g = system.env.gravity
    n = spawns.count
    born = np.zeros(n, dtype=bool)
    x, v = ballistic(spawns, np.arange(n), t_start, g)
    system.x_ref = spawns.position.copy()
    X = system.pack(x, v)

    def activate_particles(group: Group, ctx: StepContext) -> None:
        # newly born: onto their path at t; still unborn: at t + dt, where the record of
        # this step will see them (they do not move during the step)
        s = system.unpack(group.X)
        unborn = np.flatnonzero(~born)
        if unborn.size:
            newly = unborn[spawns.birth[unborn] <= ctx.t + 1e-12]
            waiting = unborn[spawns.birth[unborn] > ctx.t + 1e-12]
            if waiting.size:
                s.x[waiting], s.v[waiting] = ballistic(spawns, waiting, ctx.t + ctx.dt, g)
            if newly.size:
                s.x[newly], s.v[newly] = ballistic(spawns, newly, ctx.t, g)
                born[newly] = True
        system.active = born & (spawns.death > ctx.t)

    # keep records within the memory budget: x, v (float32) and a contact flag per record
    steps = max(1, int(math.ceil((t_end - t_start) / step)))
    per_record = max(1, n) * (3 * 4 * 2 + 1)
    stride = max(1, int(math.ceil(steps * per_record / RECORD_BUDGET)))
    system.active = np.zeros(n, dtype=bool)
    return Group(system, X, colliders, (np.zeros(0, int), np.zeros(0, int)), activate_particles, record_stride=stride, record_dtype=np.float32)
