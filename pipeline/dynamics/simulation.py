"""`simulate(loaded, t_end)` -> `Simulation`: build the world from the scene, run the fixed
list of step stages, record the states, and sample them at any times.

The step (one `StepContext`: t, dt, 1/dt, index) runs these named stages:
  activate   -> which bodies move this step (started, born and not dead, not pinned)
  integrate  -> the scene's integrator advances D(t, X) by dt (rk45 may take a smaller dt)
  collide    -> swept contacts against colliders and between bodies, impulses (collisions.py)
  guard      -> finiteness and energy bound (guard.py)
  record     -> the state at t + dt (every step, or every k-th for big particle systems)
Bodies and each particle system are separate groups: particles collide with the static
colliders only and do not act on bodies, so each group is run on its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import SceneError, SimulationError
from . import forces
from .collisions import BoxCollider, Collider, ContactBodies, MeshCollider, PlaneCollider, SphereCollider, resolve_pairs, resolve_static
from .guard import Guard
from .integrators import Integrator, make_integrator
from .particles import ParticleSamples, Spawns, ballistic, emit
from ..motion.pose import quat_to_matrix, slerp
from ..motion.rotation import transform_quat as quat_from_rotation
from .rigid import inverse_inertia_world, principal_inertia
from .shapes import BOX, CYLINDER, ShapeSet, find_contacts, resolve_shaped, true_shape_collider
from .state import BodyProps, Environment, System

if TYPE_CHECKING:
    from ..scene import LoadedScene

RECORD_BUDGET = 256 * 2**20  # bytes of recorded particle states per system


@dataclass(frozen=True)
class StepContext:
    t: float
    dt: float
    inv_dt: float
    index: int


@dataclass
class Track:
    """Recorded states of one group: times [K]; x, v [K, n, 3]; q [K, n, 4] (rigid);
    contact [K, n] (a contact happened between record k-1 and k); energies [K] (J)."""

    times: np.ndarray
    x: np.ndarray
    v: np.ndarray
    q: np.ndarray | None
    contact: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    impacts: np.ndarray  # [k, 7]: time, body, speed (m/s), other (collider index or -1 - body), centre x, y, z
    kinetic_each: np.ndarray | None = None  # [K, n] per body (body groups only), J
    potential_each: np.ndarray | None = None  # [K, n] per body, gravity (zero at x_ref) + buoyancy, J

    def interpolate(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Positions (and orientations) at `times` ([T] or [T, n], clamped to the record).

        Cubic Hermite with the recorded velocities (exact for constant acceleration);
        linear over intervals that contain a contact (the path bends there, and a
        straight line between two non-penetrating points stays out of a plane); slerp for
        orientations."""
        K, n = self.x.shape[:2]
        t = np.asarray(times, dtype=np.float64)
        if t.ndim == 1:
            t = np.broadcast_to(t[:, None], (t.size, n))
        t = np.clip(t, self.times[0], self.times[-1])
        cols = np.broadcast_to(np.arange(n)[None, :], t.shape)
        if K == 1:
            x = np.broadcast_to(self.x[0], t.shape + (3,)).astype(np.float64)
            q = None if self.q is None else np.broadcast_to(self.q[0], t.shape + (4,)).copy()
            return x, q
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, K - 2)
        h = (self.times[k + 1] - self.times[k])[..., None]
        s = ((t - self.times[k]) / h[..., 0])[..., None]
        x0, x1 = self.x[k, cols].astype(np.float64), self.x[k + 1, cols].astype(np.float64)
        v0, v1 = self.v[k, cols].astype(np.float64), self.v[k + 1, cols].astype(np.float64)
        s2, s3 = s * s, s * s * s
        hermite = (2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * x1 + (s3 - s2) * h * v1
        linear = (1 - s) * x0 + s * x1
        x = np.where(self.contact[k + 1, cols][..., None], linear, hermite)
        q = None if self.q is None else slerp(self.q[k, cols], self.q[k + 1, cols], s[..., 0])
        return x, q


# --- running a group ----------------------------------------------------------------------


@dataclass
class Group:
    """One simulated group: its system, colliders, body pairs and hooks."""

    system: System
    X: np.ndarray
    colliders: list[Collider]
    pairs: tuple[np.ndarray, np.ndarray]
    activate: Callable[["Group", StepContext], None]
    record_stride: int = 1
    record_dtype: type = np.float64
    shapes: ShapeSet | None = None  # true-shape boxes and cylinders (shapes.py)


def _bodies_activate(group: Group, ctx: StepContext) -> None:
    group.system.active = group.system.props.start <= ctx.t + 1e-12


def collide(group: Group, X0: np.ndarray, X1: np.ndarray, ctx: StepContext, iterations: int, g_mag: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The collide stage (in place on X1). Returns the per-body contact mask and impacts."""
    system = group.system
    s0, s1 = system.unpack(X0), system.unpack(X1)
    moving = system.moving()
    contact = np.zeros(system.n, dtype=bool)
    impacts: list[np.ndarray] = []
    if not group.colliders and group.pairs[0].size == 0:
        return contact, impacts
    p = system.props
    shaped = group.shapes.shaped() & moving if group.shapes is not None else np.zeros(system.n, dtype=bool)
    # the first pass's sphere sweeps, done before anything else: most steps of a small
    # system touch nothing, and then nothing more needs computing
    first_hits = []
    for col in group.colliders:
        hits = col.sweep(s0.x, s1.x, p.radius)
        hits.hit &= moving
        if true_shape_collider(col):
            hits.hit &= ~shaped  # boxes and cylinders: their true shape, below
        first_hits.append(hits)
    if not shaped.any() and group.pairs[0].size == 0 and not any(h.hit.any() for h in first_hits):
        return contact, impacts
    inv_mass = np.where(moving, p.inv_mass, 0.0)
    inv_I = None
    if system.rotating:
        inv_I = inverse_inertia_world(s1.q, np.where(moving[:, None], p.inv_inertia, 0.0))
    bodies = ContactBodies(s0.x, s0.v, s1.x, s1.v, s1.w, inv_I, p.radius, inv_mass, p.restitution, p.friction, p.static_friction)
    v_rest = max(2.0 * g_mag * ctx.dt, 1e-6)
    shaped_idx = np.flatnonzero(shaped)
    if group.shapes is not None:
        group.shapes.begin_step()
    seen = None  # shaped bodies' end positions after their last contact pass
    for iteration in range(iterations):
        found = False
        fresh = iteration == 0  # the first pass's sweeps are still valid (nothing moved since)
        if shaped_idx.size and group.colliders:
            # after the first pass only bodies that something else moved can have new contacts
            check = shaped_idx if seen is None else shaped_idx[np.any(s1.x[shaped_idx] != seen, axis=1)]
            cs = find_contacts(bodies, group.shapes, check, s0.q, s1.q, group.colliders) if check.size else None
            seen = s1.x[shaped_idx].copy()
            if cs is not None:
                found, fresh = True, False
                contact[cs.body] = True
                out = resolve_shaped(bodies, cs, group.shapes, s1.q, ctx.dt, v_rest, 4 * iterations)
                if out.shape[1]:
                    impacts.append(np.stack((ctx.t + out[3] * ctx.dt, out[0], out[1], out[2], *out[4:7]), axis=1))
        for ci, col in enumerate(group.colliders):
            if fresh:
                hits = first_hits[ci]
            else:
                hits = col.sweep(s0.x, s1.x, p.radius)
                hits.hit &= moving
                if true_shape_collider(col):
                    hits.hit &= ~shaped  # boxes and cylinders: their true shape, above
            if not hits.hit.any():
                continue
            found, fresh = True, False
            contact |= hits.hit
            out = resolve_static(bodies, hits, col, ctx.dt, v_rest)
            if out.shape[1]:
                impacts.append(np.stack((ctx.t + out[2] * ctx.dt, out[0], out[1], np.full(out.shape[1], float(ci)), *out[3:6]), axis=1))
        if group.pairs[0].size:
            out = resolve_pairs(bodies, group.pairs, ctx.dt, v_rest)
            if out.shape[1]:
                found = True
                contact[out[0].astype(int)] = True
                contact[out[1].astype(int)] = True
                impacts.append(np.stack((np.full(out.shape[1], ctx.t + ctx.dt), out[0], out[2], -1.0 - out[1], *out[3:6]), axis=1))
        if not found:
            break
    return contact, impacts


def run_group(group: Group, integrator: Integrator, t0: float, t1: float, step: float, iterations: int, guard: Guard,
              on_progress: Callable[[float, float, float], None] | None = None) -> Track:
    """Advance a group from t0 to t1 through the named stages; returns its Track.
    `on_progress(t, t0, t1)` is called every 64 steps and at the end."""
    system = group.system
    g_mag = float(np.linalg.norm(system.env.gravity))
    rec_t: list[float] = []
    rec_x: list[np.ndarray] = []
    rec_v: list[np.ndarray] = []
    rec_q: list[np.ndarray] = []
    rec_c: list[np.ndarray] = []
    rec_ke: list[float] = []
    rec_pe: list[float] = []
    rec_ke_each: list[np.ndarray] = []
    rec_pe_each: list[np.ndarray] = []
    each = bool(system.props.names)  # bodies: a few, named; energies kept per body (plots)
    impacts: list[np.ndarray] = []
    pending = np.zeros(system.n, dtype=bool)
    extra_work = system.env.wind is not None or system.env.force_field is not None

    def record(t: float, X: np.ndarray, contact: np.ndarray, energy: tuple[np.ndarray, np.ndarray, float]) -> None:
        s = system.unpack(X)
        rec_t.append(t)
        rec_x.append(s.x.astype(group.record_dtype))
        rec_v.append(s.v.astype(group.record_dtype))
        if system.rotating:
            rec_q.append(s.q.copy())
        rec_c.append(contact.copy())
        rec_ke.append(float(energy[0].sum()))
        rec_pe.append(float(energy[1].sum() + energy[2]))
        if each:
            rec_ke_each.append(energy[0])
            rec_pe_each.append(energy[1])

    ctx = StepContext(t0, 0.0, math.inf, 0)
    group.activate(group, ctx)
    X = group.X
    energy = system.energy(X)
    guard.e_in = float(energy[0].sum() + energy[1].sum() + energy[2])
    record(t0, X, pending, energy)
    t, index, h_next = t0, 0, step
    fixed = not integrator.adaptive
    while t < t1 - 1e-9 * max(1.0, abs(t1)):
        h = min(h_next, step, t1 - t)
        ctx = StepContext(t, h, 1.0 / h, index)
        # stage: activate
        before = system.moving()
        group.activate(group, ctx)
        joined = system.moving() & ~before
        if joined.any():  # bodies that start now, particles born now: their energy comes in
            kin, pot, _ = system.energy(group.X)
            guard.add_energy(float((kin + pot)[joined].sum()))
        X = group.X
        system.h = h
        # stage: integrate
        result = integrator.step(system, t, X, h)
        X1 = result.X
        ctx = StepContext(t, result.h_taken, 1.0 / result.h_taken, index)
        system.h = result.h_taken
        h_next = result.h_next
        # stage: collide
        contact, found = collide(group, X, X1, ctx, iterations, g_mag)
        impacts.extend(found)
        pending |= contact
        t = t0 + (index + 1) * step if fixed and result.h_taken == step else t + result.h_taken
        index += 1
        # stage: guard
        if extra_work:
            s1 = system.unpack(X1)
            f_ext = forces.field_force(system.props.mass, system.env.force_field, t, s1.x)
            if system.env.wind is not None:
                u = forces.wind_velocity(system.env.wind, t, s1.x)
                f_ext = f_ext + forces.drag(s1.v - u, system.props.mass, system.env.air_density, system.props.cd, system.props.area, system.props.linear, system.h) - forces.drag(
                    s1.v, system.props.mass, system.env.air_density, system.props.cd, system.props.area, system.props.linear, system.h
                )
            moving = system.moving()
            guard.add_work(ctx.dt * float(np.einsum("ij,ij->", f_ext[moving], s1.v[moving])))
        energy = system.energy(X1)
        per_body = energy[0] + energy[1]
        s1 = system.unpack(X1)
        guard.check(t, index, ctx.dt, X1, per_body, float(per_body.sum() + energy[2]), s1.x)
        group.X = X1
        # stage: record
        if index % group.record_stride == 0 or t >= t1 - 1e-9 * max(1.0, abs(t1)):
            record(t, X1, pending, energy)
            pending[:] = False
        if on_progress is not None and index % 64 == 0:
            on_progress(t, t0, t1)
    if on_progress is not None:
        on_progress(t, t0, t1)
    return Track(
        times=np.asarray(rec_t),
        x=np.stack(rec_x),
        v=np.stack(rec_v),
        q=np.stack(rec_q) if rec_q else None,
        contact=np.stack(rec_c),
        kinetic=np.asarray(rec_ke),
        potential=np.asarray(rec_pe),
        impacts=np.concatenate(impacts) if impacts else np.zeros((0, 7)),
        kinetic_each=np.stack(rec_ke_each) if each else None,
        potential_each=np.stack(rec_pe_each) if each else None,
    )


# --- building the world from the scene ----------------------------------------------------


def world_from_object(transform: object) -> np.ndarray:
    """4x4 T(translate) R(rotate) S(scale) of a scene `transform:`."""
    m = np.eye(4)
    scale = transform.scale  # type: ignore[attr-defined]
    s = np.full(3, float(scale)) if isinstance(scale, (int, float)) else np.asarray(scale, dtype=np.float64)
    m[:3, :3] = quat_to_matrix(quat_from_rotation(transform.rotate)) * s[None, :]  # type: ignore[attr-defined]
    m[:3, 3] = transform.translate  # type: ignore[attr-defined]
    return m


def _static_matrix(loaded: "LoadedScene", index: int, what: str) -> np.ndarray:
    """world_from_object of a static object (through static parents)."""
    objects = {o.name: (i, o) for i, o in enumerate(loaded.scene.objects)}
    i, obj = index, loaded.scene.objects[index]
    m = np.eye(4)
    while True:
        if obj.motion.type != "static":
            raise SceneError([loaded.source.problem(("objects", i, "motion"), f"{what} must not move: '{obj.name}' has {obj.motion.type} motion (moving colliders and emitters are not simulated)")])
        m = world_from_object(obj.transform) @ m
        if obj.parent is None:
            return m
        i, obj = objects[obj.parent]


def _scale3(transform: object) -> np.ndarray:
    s = transform.scale  # type: ignore[attr-defined]
    return np.full(3, float(s)) if isinstance(s, (int, float)) else np.asarray(s, dtype=np.float64)


def build_colliders(loaded: "LoadedScene") -> list[Collider]:
    out: list[Collider] = []
    for i, obj in enumerate(loaded.scene.objects):
        c = obj.collider
        if c is None or obj.motion.type == "dynamics":
            continue
        m = _static_matrix(loaded, i, "a collider")
        cols = m[:3, :3]
        norms = np.linalg.norm(cols, axis=0)
        rot = cols / norms[None, :]
        origin = m[:3, 3].copy()
        base = dict(name=obj.name, restitution=c.restitution, friction=c.friction, static_friction=c.static_friction if c.static_friction is not None else c.friction)
        if obj.shape in ("rectangle", "disk"):
            normal = np.cross(cols[:, 0], cols[:, 1])
            normal /= np.linalg.norm(normal)
            if obj.shape == "rectangle":
                out.append(PlaneCollider(**base, point=origin, normal=normal, u=rot[:, 0], v=rot[:, 1], half_u=obj.width / 2 * norms[0], half_v=obj.height / 2 * norms[1]))
            else:
                out.append(PlaneCollider(**base, point=origin, normal=normal, u=rot[:, 0], v=rot[:, 1], disk_radius=obj.radius * float(norms[:2].max())))
        elif obj.shape == "cube":
            size = np.full(3, float(obj.size)) if isinstance(obj.size, (int, float)) else np.asarray(obj.size)
            out.append(BoxCollider(**base, center=origin, rotation=rot, half=size / 2 * norms))
        elif obj.shape == "sphere":
            out.append(SphereCollider(**base, center=origin, radius=obj.radius * float(norms.max())))
        elif obj.shape == "mesh":
            from ..meshes import load_mesh

            verts, tris = load_mesh(loaded.asset(obj.file))
            world = verts @ cols.T + origin
            out.append(MeshCollider(**base, triangles=world[tris]))
        else:
            raise SceneError([loaded.source.problem(("objects", i, "collider"), f"a {obj.shape} cannot be a collider (use rectangle, disk, cube, sphere or mesh)")])
    return out


def _shape_numbers(loaded: "LoadedScene", obj: object) -> tuple[dict[str, float], float, float]:
    """(inertia dims, bounding radius, volume) of a body's shape with its scale applied."""
    s = _scale3(obj.transform)  # type: ignore[attr-defined]
    shape = obj.shape  # type: ignore[attr-defined]
    if shape == "sphere":
        r = obj.radius * float(s.max())  # type: ignore[attr-defined]
        return {"radius": r}, r, 4.0 / 3.0 * math.pi * r**3
    if shape == "cube":
        size = obj.size  # type: ignore[attr-defined]
        dims = (np.full(3, float(size)) if isinstance(size, (int, float)) else np.asarray(size)) * s
        return {"sx": dims[0], "sy": dims[1], "sz": dims[2]}, float(np.linalg.norm(dims)) / 2, float(np.prod(dims))
    if shape == "cylinder":
        r, h = obj.radius * float(max(s[0], s[2])), obj.height * s[1]  # type: ignore[attr-defined]
        return {"radius": r, "height": h}, math.hypot(r, h / 2), math.pi * r * r * h
    if shape == "rectangle":
        w, h = obj.width * s[0], obj.height * s[1]  # type: ignore[attr-defined]
        return {"width": w, "height": h}, math.hypot(w, h) / 2, 0.0
    if shape == "disk":
        r = obj.radius * float(s[:2].max())  # type: ignore[attr-defined]
        return {"radius": r}, r, 0.0
    if shape == "mesh":
        from ..meshes import load_mesh

        verts, tris = load_mesh(loaded.asset(obj.file))  # type: ignore[attr-defined]
        verts = verts * s
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        # closed-mesh volume: sum of signed tetrahedra (0, a, b, c) = a . (b x c) / 6
        tri = verts[tris]
        vol = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0)
        dims = hi - lo
        return {"sx": dims[0], "sy": dims[1], "sz": dims[2]}, float(np.linalg.norm(verts, axis=1).max()), vol or float(np.prod(dims))
    return {}, 0.05, 4.0 / 3.0 * math.pi * 0.05**3


def build_environment(loaded: "LoadedScene", names: list[str]) -> Environment:
    d = loaded.scene.dynamics
    from ..motion.expr import parse_expression

    def parse(texts: tuple[str, str, str] | None) -> tuple[object, object, object] | None:
        if texts is None:
            return None
        return tuple(parse_expression(t, ("t", "x", "y", "z")) for t in texts)  # type: ignore[return-value]

    springs = None
    if d.springs:
        index = {n: i for i, n in enumerate(names)}
        springs = forces.SpringSet(
            a=np.array([index[s.a] for s in d.springs]),
            b=np.array([index[s.b] for s in d.springs]),
            stiffness=np.array([s.stiffness for s in d.springs]),
            damping=np.array([s.damping for s in d.springs]),
            rest=np.full(len(d.springs), np.nan),
        )
        springs_rest = [s.rest_length for s in d.springs]
        object.__setattr__(springs, "rest", np.array([np.nan if r is None else r for r in springs_rest]))
    return Environment(
        gravity=np.asarray(d.gravity, dtype=np.float64),
        air_density=d.air_density,
        wind=parse(d.wind),
        force_field=parse(d.force_field),
        fluids=[forces.HalfSpaceFluid(f.level, f.density, f.drag_cd) for f in d.fluids],
        springs=springs,
        newtonian=None if d.newtonian_gravity is None else (d.newtonian_gravity.G, d.newtonian_gravity.softening),
    )


def build_bodies(loaded: "LoadedScene", t_start: float) -> tuple[Group, list[np.ndarray]] | None:
    """The group of dynamics bodies (None if the scene has none) and their scales."""
    objs = [o for o in loaded.scene.objects if o.motion.type == "dynamics"]
    if not objs:
        return None
    n = len(objs)
    names = [o.name for o in objs]
    cols: dict[str, list[float] | list[np.ndarray]] = {k: [] for k in ("mass", "inv_mass", "radius", "radius_eq", "area", "cd", "linear", "restitution", "friction", "static_friction", "start", "inertia", "inv_inertia")}
    x, v, q, w, scales = [], [], [], [], []
    kind, half = np.zeros(n, dtype=np.int64), np.zeros((n, 3))
    for k_obj, o in enumerate(objs):
        m = o.motion
        dims, radius, volume = _shape_numbers(loaded, o)
        r_eq = (3.0 * max(volume, 1e-12) / (4.0 * math.pi)) ** (1.0 / 3.0)
        inertia = principal_inertia(o.shape if dims else "empty", m.mass, dims)
        rigid = m.body == "rigid" and not m.pinned
        if o.shape == "cube":
            kind[k_obj], half[k_obj] = BOX, [dims["sx"] / 2, dims["sy"] / 2, dims["sz"] / 2]
        elif o.shape == "cylinder":
            kind[k_obj], half[k_obj] = CYLINDER, [dims["radius"], dims["height"] / 2, dims["radius"]]
        vals = dict(
            mass=m.mass,
            inv_mass=0.0 if m.pinned else 1.0 / m.mass,
            radius=radius,
            radius_eq=r_eq,
            area=(m.drag.area if m.drag and m.drag.area else math.pi * (dims["radius"] if o.shape == "sphere" else r_eq) ** 2),
            cd=m.drag.cd if m.drag else 0.0,
            linear=m.drag.linear if m.drag else 0.0,
            restitution=m.restitution,
            friction=m.friction,
            static_friction=m.static_friction if m.static_friction is not None else m.friction,
            start=m.start,
            inertia=inertia,
            inv_inertia=1.0 / inertia if rigid else np.zeros(3),
        )
        for k, val in vals.items():
            cols[k].append(val)  # type: ignore[arg-type]
        x.append(o.transform.translate)
        q.append(quat_from_rotation(o.transform.rotate))
        v.append((0.0, 0.0, 0.0) if m.pinned else m.velocity)
        w.append(np.radians(m.angular_velocity) if rigid else np.zeros(3))
        scales.append(_scale3(o.transform))
    props = BodyProps(names=names, **{k: np.asarray(val, dtype=np.float64) for k, val in cols.items()})
    env = build_environment(loaded, names)
    x_arr = np.asarray(x, dtype=np.float64)
    if env.springs is not None:
        rest = env.springs.rest
        init = np.linalg.norm(x_arr[env.springs.b] - x_arr[env.springs.a], axis=1)
        object.__setattr__(env.springs, "rest", np.where(np.isnan(rest), init, rest))
    system = System(props, env, rotating=True)
    system.x_ref = x_arr.copy()
    X = system.pack(x_arr, np.asarray(v, dtype=np.float64), np.asarray(q), np.asarray(w, dtype=np.float64))
    pairs = np.triu_indices(n, 1)
    group = Group(system, X, build_colliders(loaded), (pairs[0], pairs[1]), _bodies_activate, shapes=ShapeSet(kind, half))
    return group, scales


def _particle_group(loaded: "LoadedScene", index: int, spawns: Spawns, colliders: list[Collider], t_start: float, t_end: float, step: float) -> Group:
    obj = loaded.scene.objects[index]
    e = obj.emitter
    n = spawns.count
    radius = obj.radius * float(_scale3(obj.transform).max())
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

    def activate(group: Group, ctx: StepContext) -> None:
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
    return Group(system, X, colliders, (np.zeros(0, int), np.zeros(0, int)), activate, record_stride=stride, record_dtype=np.float32)


# --- the result ---------------------------------------------------------------------------


@dataclass
class ParticleSystem:
    name: str
    spawns: Spawns
    track: Track


@dataclass
class Simulation:
    """Recorded dynamics of a scene between t_start and t_end, sampled at any times.

    Times outside [t_start, t_end] are clamped (bodies hold their first / last state)."""

    t_start: float
    t_end: float
    integrator: str
    step: float
    body_names: list[str]
    body_scales: list[np.ndarray]
    bodies: Track | None
    systems: dict[str, ParticleSystem]
    collider_names: list[str]
    gravity: np.ndarray | None = None  # m/s^2
    body_mass: np.ndarray | None = None  # kg, per body
    body_start: np.ndarray | None = None  # [n, 3] m, where each body's gravity potential was zero in the track
    flocks: dict[str, "object"] = field(default_factory=dict)  # FlockTrack by object name (flock.py)
    followers: dict[str, "object"] = field(default_factory=dict)  # plan.FollowerTrack by object name

    def follower(self, name: str) -> "object":
        """The simulated follower (motion/plan.py FollowerTrack) of the planned object `name`."""
        if name not in self.followers:
            raise SimulationError(f"no planned-path follower named '{name}' (have: {', '.join(self.followers) or 'none'})")
        return self.followers[name]

    def flock(self, name: str) -> "object":
        """The recorded agents (flock.FlockTrack) of the flock object `name`."""
        if name not in self.flocks:
            raise SimulationError(f"no flock named '{name}' (have: {', '.join(self.flocks) or 'none'})")
        return self.flocks[name]

    def sample(self, times: np.ndarray) -> dict[str, "object"]:
        """World-space Pose of every dynamics body at `times` (seconds, any order)."""
        from ..motion import Pose

        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if self.bodies is None:
            return {}
        x, q = self.bodies.interpolate(times)
        assert q is not None
        return {
            name: Pose(np.ascontiguousarray(x[:, i]), np.ascontiguousarray(q[:, i]), np.broadcast_to(self.body_scales[i], (times.size, 3)).copy())
            for i, name in enumerate(self.body_names)
        }

    def particles(self, name: str, times: np.ndarray) -> ParticleSamples:
        """Particles of the system `name` at `times`: ids, positions [T, n, 3], alive [T, n]."""
        if name not in self.systems:
            raise SimulationError(f"no particle system named '{name}' (have: {', '.join(self.systems) or 'none'})")
        ps = self.systems[name]
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        n = ps.spawns.count
        if n == 0:
            return ParticleSamples(np.zeros(0, dtype=np.int64), np.zeros((times.size, 0, 3)), np.zeros((times.size, 0), dtype=bool))
        alive = (times[:, None] >= ps.spawns.birth[None, :] - 1e-12) & (times[:, None] < ps.spawns.death[None, :])
        # before birth: at the spawn point; after death: where it died
        clamped = np.clip(times[:, None], ps.spawns.birth[None, :], ps.spawns.death[None, :])
        x, _ = ps.track.interpolate(clamped)
        return ParticleSamples(np.arange(n, dtype=np.int64), x, alive)

    @property
    def particle_systems(self) -> list[str]:
        return list(self.systems)

    def body_energy(self) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """(body, times, kinetic, potential) per dynamics body, in J. The potential's zero
        is the plane through the world origin perpendicular to gravity (height 0 for
        g along -Y): U = -m g . x, plus buoyancy. Shared terms (springs, gravity between
        bodies) are not in any one body's energy: `energy()` has the group's total."""
        b = self.bodies
        if b is None or b.kinetic_each is None or self.gravity is None:
            return []
        # the track's potential is zero at each body's start: shift by -m g . x_start
        shift = -self.body_mass * (self.body_start @ self.gravity)
        return [(name, b.times, b.kinetic_each[:, i], b.potential_each[:, i] + shift[i]) for i, name in enumerate(self.body_names)]

    def energy(self) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """(label, times, kinetic, potential) per group, in J, for plots."""
        out = []
        if self.bodies is not None:
            out.append(("bodies", self.bodies.times, self.bodies.kinetic, self.bodies.potential))
        for name, ps in self.systems.items():
            out.append((name, ps.track.times, ps.track.kinetic, ps.track.potential))
        return out


def simulate(loaded: "LoadedScene", t_end: float, t_start: float = 0.0, on_progress: Callable[[float, float, float], None] | None = None) -> Simulation:
    """Simulate every dynamics body and particle system of the scene from t_start to t_end.

    `on_progress(t, t_start, t_end)` is called every few steps of each group (bodies first,
    then each particle system) with the time simulated so far."""
    if not (math.isfinite(t_start) and math.isfinite(t_end)) or t_end < t_start:
        raise SimulationError(f"cannot simulate from t = {t_start} s to t = {t_end} s")
    d = loaded.scene.dynamics
    integrator = make_integrator(d.integrator, d.rtol, d.atol)
    g_mag = float(np.linalg.norm(d.gravity))
    built = build_bodies(loaded, t_start)
    track, names, scales = None, [], []
    mass = start = None
    colliders = build_colliders(loaded)
    if built is not None:
        group, scales = built
        names = group.system.props.names
        p = group.system.props
        mass, start = p.mass.copy(), group.system.x_ref.copy()
        guard = Guard(names, d.integrator, d.energy_growth_limit, 0.0, float((p.mass * g_mag * p.radius).sum()) + 1e-9)
        track = run_group(group, integrator, t_start, t_end, d.step, d.contact_iterations, guard, on_progress)
    systems: dict[str, ParticleSystem] = {}
    for i, obj in enumerate(loaded.scene.objects):
        if obj.shape != "particles":
            continue
        m = _static_matrix(loaded, i, "a particle emitter")
        spawns = emit(obj.emitter, m, t_end)
        group = _particle_group(loaded, i, spawns, colliders, t_start, t_end, d.step)
        p = group.system.props
        guard = Guard([f"{obj.name}[{k}]" for k in range(spawns.count)] if spawns.count <= 100_000 else [obj.name], d.integrator, d.energy_growth_limit, 0.0,
                      float((p.mass * g_mag * np.maximum(p.radius, 1e-3)).sum()) + 1e-9)
        systems[obj.name] = ParticleSystem(obj.name, spawns, run_group(group, integrator, t_start, t_end, d.step, d.contact_iterations, guard, on_progress))
    flocks: dict[str, object] = {}
    for i, obj in enumerate(loaded.scene.objects):
        if getattr(getattr(obj, "deform", None), "type", None) == "flock":
            from .flock import FlockParams, check_instance_budget, simulate_flock

            check_instance_budget(loaded, i)
            flocks[obj.name] = simulate_flock(FlockParams.from_spec(obj.deform), colliders, t_start, t_end, obj.name)
    followers: dict[str, object] = {}
    for i, obj in enumerate(loaded.scene.objects):
        if obj.motion.type == "plan" and obj.motion.follower is not None:
            from ..motion.plan import simulate_follower

            followers[obj.name] = simulate_follower(loaded, i, t_start, t_end)
    return Simulation(t_start, t_end, d.integrator, d.step, names, scales, track, systems, [c.name for c in colliders],
                      np.asarray(d.gravity, dtype=np.float64), mass, start, flocks, followers)
