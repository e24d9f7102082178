"""One simulation step as named stages over one `StepContext`, and the run of a group.

Each step of a group runs, in order:
  activate   -> which bodies move this step (started, born and not dead, not pinned);
                bodies that join bring their energy into the guard's budget
  integrate  -> the scene's integrator advances D(t, X) by dt (rk45 may take a smaller dt)
  collide    -> swept contacts against colliders and between bodies, impulses (collisions.py;
                boxes on boxes: island.py)
  constrain  -> joints (joints.py)
  springs    -> penalty contacts' static-friction springs follow the step's slip (penalty.py)
  guard      -> finiteness and energy bound (guard.py)
  record     -> the state at t + dt (every step, or every k-th for big particle systems)
When nothing in a body group can change its acceleration (uniform gravity only, nothing
spinning, no body starting) the `coast` stage replaces the next steps, up to the first one
with a possible contact, by the integrator's closed form under a constant acceleration,
computed for all of them at once (see `coast`).
The step size reaches the forces (drag and friction never reverse a velocity within a
step) through the context: the integrator advances a `StepDynamics`, the system's
D(t, X) bound to the step's dt, never through state kept on the system.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import forces
from ..errors import SimulationError
from .collisions import Collider, ContactBodies, Hits, _sweep_spheres, resolve_pairs, resolve_static, sweep_collider
from .guard import Guard
from ..motion.pose import quat_exp, quat_mul
from .integrators import Integrator
from . import island
from .joints import JointSet, constrain
from .penalty import handles
from .rigid import inverse_inertia_world
from .shapes import ShapeSet, find_contacts, resolve_shaped, true_shape_collider
from .state import System
from .track import Track


@dataclass(frozen=True)
class StepContext:
    """One step: it starts at `t` (s) and lasts `dt` (s; once integrated, the step the
    integrator took), `inv_dt` = 1/dt, `index` counts steps from 0, and `t_next` is the
    time the step ends (exact on the fixed grid t0 + (index + 1) step; nan before the
    integrate stage decided it)."""

    t: float
    dt: float
    inv_dt: float
    index: int
    t_next: float = math.nan


class StepDynamics:
    """A system's D(t, X) bound to one step's dt: what an integrator advances (see
    integrators.StepSystem). Drag and friction read the step size from here."""

    __slots__ = ("system", "dt", "split")

    def __init__(self, system: System, dt: float) -> None:
        self.system = system
        self.dt = dt
        self.split = system.split

    def derivative(self, t: float, X: np.ndarray) -> np.ndarray:
        """D(t, X) with this step's dt."""
        return self.system.derivative(t, X, self.dt)

    def velocity_rate(self, t: float, X: np.ndarray) -> np.ndarray:
        """The velocity-like part of D with this step's dt."""
        return self.system.velocity_rate(t, X, self.dt)

    def position_rate(self, t: float, X: np.ndarray) -> np.ndarray:
        """The position-like part of D (no forces, no dt)."""
        return self.system.position_rate(t, X)

    def normalize(self, X: np.ndarray) -> np.ndarray:
        """Back onto the state manifold (unit quaternions)."""
        return self.system.normalize(X)


@dataclass
class Group:
    """One simulated group: its system, state X, colliders, body pairs and activate hook."""

    system: System
    X: np.ndarray
    colliders: list[Collider]
    pairs: tuple[np.ndarray, np.ndarray]
    activate: Callable[["Group", StepContext], None]
    record_stride: int = 1
    record_dtype: type = np.float64
    shapes: ShapeSet | None = None  # true-shape boxes and cylinders (shapes.py)
    joints: "JointSet | None" = None  # joints between bodies and to the world (joints.py)

    @property
    def kinematic(self) -> bool:
        """Whether a collider of the group moves (kinematic.py): no coasting then."""
        return any(col.motion is not None for col in self.colliders)


def bodies_activate(group: Group, ctx: StepContext) -> None:
    """The activate hook of rigid bodies: a body moves from its `start` time on. Steps lie
    on the fixed grid, so a body whose start falls inside a step joins at the step's end;
    it first catches up on the part of that step after its start (`catch_up`), so a
    release does not lag by up to one step (a 200 m/s launch by a metre at 1/192 s)."""
    system = group.system
    before = system.active
    now = system.props.start <= ctx.t + 1e-12
    system.active = now
    if ctx.dt > 0:  # (the run's first call places nothing: the state is the start pose)
        late = np.flatnonzero(now & ~before & (ctx.t - system.props.start > 1e-12))
        if late.size:
            catch_up(group, late, ctx.t - system.props.start[late])


def catch_up(group: Group, index: np.ndarray, tau: np.ndarray) -> None:
    """Advance bodies `index` by tau [k] seconds each (less than one step) from their start
    pose and velocity, under the acceleration there held constant: x + v tau + a tau^2 / 2,
    v + a tau, orientation turned by w tau. Exact in free flight under gravity; to first
    order under drag, springs or fields (what one explicit step would do), and contacts
    within tau are left to the next step's sweep, which starts from this state."""
    system = group.system
    s = system.unpack(group.X)
    tau_v = tau[:, None]
    acc = system.acceleration(float(system.props.start[index].min()), s.x, s.v, float(tau.max()))[index]
    s.x[index] += s.v[index] * tau_v + 0.5 * acc * tau_v * tau_v
    s.v[index] += acc * tau_v
    if system.rotating and s.q is not None and s.w is not None and s.w[index].any():
        s.q[index] = quat_mul(quat_exp(s.w[index] * tau_v), s.q[index])


def activate(group: Group, ctx: StepContext, guard: Guard) -> None:
    """Stage activate: the group's hook marks the bodies that move this step; the energy
    of those that join now (bodies that start, particles born) enters the guard's budget."""
    system = group.system
    before = system.moving()
    group.activate(group, ctx)
    joined = system.moving() & ~before
    if joined.any():
        kin, pot, _ = system.energy(group.X)
        guard.add_energy(float((kin + pot)[joined].sum()))


def integrate(group: Group, integrator: Integrator, ctx: StepContext, t0: float, step: float) -> tuple[np.ndarray, StepContext, float]:
    """Stage integrate: advance the group's state by ctx.dt. Returns the new state, the
    context of the step actually taken (its dt, and t_next on the fixed grid t0 +
    (index + 1) step when the whole step was taken by a fixed-step method) and the step
    the integrator proposes next."""
    result = integrator.step(StepDynamics(group.system, ctx.dt), ctx.t, group.X, ctx.dt)
    h = result.h_taken
    on_grid = not integrator.adaptive and h == step
    t_next = t0 + (ctx.index + 1) * step if on_grid else ctx.t + h
    return result.X, StepContext(ctx.t, h, 1.0 / h, ctx.index, t_next), result.h_next


def collide(group: Group, X0: np.ndarray, X1: np.ndarray, ctx: StepContext, iterations: int, g_mag: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Stage collide: swept contacts of the step X0 -> X1 against the colliders and between
    bodies, resolved by impulses in place on X1 (collisions.py, shapes.py). Returns the
    per-body contact mask and the impacts ([k, 7] rows, see Track.impacts)."""
    system = group.system
    s0, s1 = system.unpack(X0), system.unpack(X1)
    moving = system.moving()
    contact = np.zeros(system.n, dtype=bool)
    impacts: list[np.ndarray] = []
    if not group.colliders and group.pairs[0].size == 0:
        return contact, impacts
    p = system.props
    # penalty bodies: their contacts with plane, sphere and box colliders and with each other
    # are forces inside D (penalty.py); against mesh colliders and impulse bodies, impulses
    penalty = system.penalty.body if system.penalty is not None else None
    impulse = moving if penalty is None else moving & ~penalty
    shaped = group.shapes.shaped() & impulse if group.shapes is not None else np.zeros(system.n, dtype=bool)
    pairs = group.pairs
    if penalty is not None and pairs[0].size:
        keep = ~(penalty[pairs[0]] & penalty[pairs[1]])
        pairs = (pairs[0][keep], pairs[1][keep])

    def sweep(col: Collider) -> Hits:
        """The moving bodies' sphere sweeps against `col` (boxes and cylinders against
        plane, box and sphere colliders: their true shape, below)."""
        hits = sweep_collider(col, s0.x, s1.x, p.radius, ctx.t, ctx.t + ctx.dt)
        hits.hit &= impulse if penalty is not None and handles(col) else moving
        if true_shape_collider(col):
            hits.hit &= ~shaped
        return hits

    # the first pass's sphere sweeps, done before anything else: most steps of a small
    # system touch nothing, and then nothing more needs computing
    first_hits = [sweep(col) for col in group.colliders]
    if not shaped.any() and pairs[0].size == 0 and not any(h.hit.any() for h in first_hits):
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
    stacked, pairs = _box_pairs(group, shaped, pairs)
    for iteration in range(iterations):
        found = False
        fresh = iteration == 0  # the first pass's sweeps are still valid (nothing moved since)
        if shaped_idx.size and (group.colliders or stacked is not None):
            # after the first pass only bodies that something else moved can have new contacts
            check = shaped_idx if seen is None else shaped_idx[np.any(s1.x[shaped_idx] != seen, axis=1)]
            done = _shaped_pass(group, bodies, s0.q, s1.q, check, stacked if iteration == 0 else None, ctx, v_rest, iterations)
            seen = s1.x[shaped_idx].copy()
            if done is not None:
                found, fresh, contact[done[0]], out = True, False, True, done[1]
                if out.shape[1]:
                    impacts.append(np.stack((ctx.t + out[3] * ctx.dt, out[0], out[1], out[2], *out[4:7]), axis=1))
        for ci, col in enumerate(group.colliders):
            hits = first_hits[ci] if fresh else sweep(col)
            if not hits.hit.any():
                continue
            found, fresh = True, False
            contact |= hits.hit
            out = resolve_static(bodies, hits, col, ctx.dt, v_rest, ctx.t)
            if out.shape[1]:
                impacts.append(np.stack((ctx.t + out[2] * ctx.dt, out[0], out[1], np.full(out.shape[1], float(ci)), *out[3:6]), axis=1))
        if pairs[0].size:
            out = resolve_pairs(bodies, pairs, ctx.dt, v_rest)
            if out.shape[1]:
                found = True
                contact[out[0].astype(int)] = True
                contact[out[1].astype(int)] = True
                impacts.append(np.stack((np.full(out.shape[1], ctx.t + ctx.dt), out[0], out[2], -1.0 - out[1], *out[3:6]), axis=1))
        if not found:
            break
    return contact, impacts


def _box_pairs(group: Group, shaped: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> tuple[tuple[np.ndarray, np.ndarray] | None, tuple[np.ndarray, np.ndarray]]:
    """The body pairs split into box pairs (None: none), solved with the boxes' other
    contacts as one set (island.py), and the rest (bounding spheres)."""
    if group.shapes is None or pairs[0].size == 0:
        return None, pairs
    box = island.box_pairs(group.shapes.kind, shaped, pairs)
    if not box.any():
        return None, pairs
    return (pairs[0][box], pairs[1][box]), (pairs[0][~box], pairs[1][~box])


def _shaped_pass(group: Group, bodies: ContactBodies, q0: np.ndarray, q1: np.ndarray, check: np.ndarray,
                 stacked: tuple[np.ndarray, np.ndarray] | None, ctx: StepContext, v_rest: float, iterations: int) -> tuple[np.ndarray, np.ndarray] | None:
    """One contact pass of the true-shape bodies `check`: their contacts with static colliders,
    and with each other for the box pairs `stacked`. Boxes touching boxes are solved with all
    these contacts as one set (island.py); otherwise each body alone (shapes.py). Returns the
    bodies in contact and the impacts ([7, k], see resolve_shaped), or None."""
    shapes = group.shapes
    if shapes is None:
        return None
    cs = find_contacts(bodies, shapes, check, q0, q1, group.colliders) if check.size and group.colliders else None
    if stacked is not None:
        g = group.system.env.gravity
        g_mag = float(np.linalg.norm(g))
        rows = island.pair_contacts(bodies, shapes, q1, stacked[0], stacked[1], 2.0 * g_mag * ctx.dt**2 + 1e-6)
        if rows:
            if cs is not None:
                rows.insert(0, island.static_rows(bodies, cs, shapes))
            f = island.flatten(rows)
            up = -g / g_mag if g_mag > 0 else np.array([0.0, 1.0, 0.0])
            out = island.solve(bodies, f, shapes, q1, ctx.dt, v_rest, 4 * iterations, up)
            return np.concatenate((f.b, f.a[f.a >= 0])), out
    if cs is None:
        return None
    return cs.body, resolve_shaped(bodies, cs, shapes, q1, ctx.dt, v_rest, 4 * iterations)


def hold_joints(group: Group, X1: np.ndarray, ctx: StepContext) -> None:
    """Stage constrain: the joints project the end-of-step state X1 (in place) back onto
    their constraints, positions then velocities (joints.py); held and pinned bodies are
    infinite mass."""
    system = group.system
    s1 = system.unpack(X1)
    move = system.moving()
    p = system.props
    constrain(group.joints, s1.x, s1.q, s1.v, s1.w, np.where(move, p.inv_mass, 0.0), np.where(move[:, None], p.inv_inertia, 0.0), ctx.dt)


def advance_springs(group: Group, X1: np.ndarray, ctx: StepContext) -> None:
    """Stage springs: the penalty contacts' static-friction springs follow the step's slip
    (penalty.PenaltySet.advance), at the end-of-step state X1."""
    system = group.system
    if system.penalty is None:
        return
    s1 = system.unpack(X1)
    system.penalty.advance(s1.x, s1.q, s1.v, s1.w, system.moving(), ctx.dt, ctx.t_next)


def guard_step(group: Group, guard: Guard, X1: np.ndarray, ctx: StepContext) -> tuple[np.ndarray, np.ndarray, float]:
    """Stage guard: the positive work of wind and force fields over the step enters the
    budget, then the state at ctx.t_next must be finite and within the energy bound
    (guard.py). Returns the energies of X1 (kinetic [n], potential [n], shared)."""
    system = group.system
    env, p = system.env, system.props
    if env.wind is not None or env.force_field is not None:
        s1 = system.unpack(X1)
        f_ext = forces.field_force(p.mass, env.force_field, ctx.t_next, s1.x)
        if env.wind is not None:
            u = forces.wind_velocity(env.wind, ctx.t_next, s1.x)
            f_ext = f_ext + forces.drag(s1.v - u, p.mass, env.air_density, p.cd, p.area, p.linear, ctx.dt) - forces.drag(
                s1.v, p.mass, env.air_density, p.cd, p.area, p.linear, ctx.dt
            )
        moving = system.moving()
        guard.add_work(ctx.dt * float(np.einsum("ij,ij->", f_ext[moving], s1.v[moving])))
    if group.kinematic:  # what moving colliders did to the bodies (their impulses, penalty forces)
        for col in group.colliders:
            if col.motion is not None:
                col.motion.now = ctx.t_next
                guard.add_work(col.motion.take_work())
        if system.penalty is not None:
            s1 = system.unpack(X1)
            guard.add_work(ctx.dt * system.penalty.collider_power(s1.x, s1.q, s1.v, system.moving(), ctx.t_next))
    energy = system.energy(X1)
    per_body = energy[0] + energy[1]
    s1 = system.unpack(X1)
    guard.check(ctx.t_next, ctx.index + 1, ctx.dt, X1, per_body, float(per_body.sum() + energy[2]), s1.x)
    return energy


class Rows:
    """Records of one quantity ([K, ...] of `dtype`), kept in one array that grows by
    doubling: appending converts in place, and the result is a view, with no stacking
    copy at the end (a 100k-particle group records ~1 MB a record)."""

    def __init__(self, shape: tuple[int, ...], dtype: type, capacity: int) -> None:
        self.data = np.empty((max(1, capacity),) + shape, dtype=dtype)
        self.k = 0

    def _room(self, count: int) -> None:
        if self.k + count > len(self.data):
            grown = np.empty((max(2 * len(self.data), self.k + count),) + self.data.shape[1:], dtype=self.data.dtype)
            grown[: self.k] = self.data[: self.k]
            self.data = grown

    def append(self, row: np.ndarray) -> None:
        """Keep one record."""
        self._room(1)
        self.data[self.k] = row
        self.k += 1

    def extend(self, rows: np.ndarray) -> None:
        """Keep K records ([K, ...]; a broadcast view is fine)."""
        self._room(len(rows))
        self.data[self.k : self.k + len(rows)] = rows
        self.k += len(rows)

    def array(self) -> np.ndarray:
        """Everything kept, [K, ...]."""
        return self.data[: self.k]


class Recorder:
    """Stage record: keeps the group's states (in its record dtype) and energies; `track()`
    returns them as a Track. `expected`: about how many records the run will keep."""

    def __init__(self, group: Group, expected: int = 16) -> None:
        self.group = group
        system = group.system
        n, dtype = system.n, group.record_dtype
        self.each = bool(system.props.names)  # bodies: a few, named; energies kept per body (plots)
        self.t: list[float] = []
        self.x = Rows((n, 3), dtype, expected)
        self.v = Rows((n, 3), dtype, expected)
        self.q = Rows((n, 4), np.float64, expected) if system.rotating else None
        self.c = Rows((n,), bool, expected)
        self.ke: list[float] = []
        self.pe: list[float] = []
        self.ke_each = Rows((n,), np.float64, expected) if self.each else None
        self.pe_each = Rows((n,), np.float64, expected) if self.each else None
        self.impacts: list[np.ndarray] = []

    def record(self, t: float, X: np.ndarray, contact: np.ndarray, energy: tuple[np.ndarray, np.ndarray, float]) -> None:
        """Keep the state X at time t, whether a contact happened since the last record,
        and its energies (kinetic [n], potential [n], shared)."""
        s = self.group.system.unpack(X)
        self.t.append(t)
        self.x.append(s.x)
        self.v.append(self._held_still(s.v))
        if self.q is not None:
            self.q.append(s.q)
        self.c.append(contact)
        self.ke.append(float(energy[0].sum()))
        self.pe.append(float(energy[1].sum() + energy[2]))
        if self.ke_each is not None and self.pe_each is not None:
            self.ke_each.append(energy[0])
            self.pe_each.append(energy[1])

    def record_many(self, t: np.ndarray, x: np.ndarray, v: np.ndarray, q: np.ndarray | None, kinetic: np.ndarray, potential: np.ndarray,
                    contact: np.ndarray) -> None:
        """Keep K states at once (coast: per-body energies [K, n], no shared terms): times
        [K], x and v [K, n, 3], one orientation [n, 4] for all, and the bodies [n] in
        contact throughout (at rest on a support)."""
        K = len(t)
        self.t.extend(t.tolist())
        self.x.extend(x)
        self.v.extend(self._held_still(v))
        if self.q is not None and q is not None:
            self.q.extend(np.broadcast_to(q, (K,) + q.shape))
        self.c.extend(np.broadcast_to(contact, (K, x.shape[1])))
        self.ke.extend(kinetic.sum(axis=1).tolist())
        self.pe.extend(potential.sum(axis=1).tolist())
        if self.ke_each is not None and self.pe_each is not None:
            self.ke_each.extend(kinetic)
            self.pe_each.extend(potential)

    def _held_still(self, v: np.ndarray) -> np.ndarray:
        """Velocities [..., n, 3] as recorded: 0 for bodies that do not move (before their
        start, pinned), whose state keeps the velocity they start with; the track's cubic
        Hermite would otherwise swing a held body by up to h |v| / 10 between records.
        (Particles not yet born ride their ballistic path: their velocity is their motion.)"""
        move = self.group.system.moving()
        if not self.each or move.all():
            return v
        return np.where(move[:, None], v, 0.0)

    def track(self) -> Track:
        """Everything recorded, as one Track."""
        return Track(
            times=np.asarray(self.t),
            x=self.x.array(),
            v=self.v.array(),
            q=self.q.array() if self.q is not None else None,
            contact=self.c.array(),
            kinetic=np.asarray(self.ke),
            potential=np.asarray(self.pe),
            impacts=np.concatenate(self.impacts) if self.impacts else np.zeros((0, 7)),
            kinetic_each=self.ke_each.array() if self.ke_each is not None else None,
            potential_each=self.pe_each.array() if self.pe_each is not None else None,
        )


COAST_STEPS = 512  # steps one coast batch looks ahead at most
# m/s: a body this slow on a level support is at rest (the collide stage leaves it in
# place). Holding it through a coast moves it less than 1e-9 m per second coasted.
REST_SPEED = 1e-9
# rad/s: spin this slow is rounding left by friction on a contact without slip (about
# 1e-14 after a bounce); a coast keeps orientations as they are, so it turns a body by
# less than 1e-9 rad per second coasted from where stepping would.
REST_SPIN = 1e-9


def resting(group: Group, x: np.ndarray, v: np.ndarray, move: np.ndarray, a: np.ndarray, step: float) -> np.ndarray:
    """Bodies [n] at rest on a level support: moving, sphere-shaped for collisions (boxes and
    cylinders need their true shape), slower than REST_SPEED, and one step of free fall
    from where they are would meet a collider whose normal is opposite their constant
    acceleration a [n, 3] (to 1e-9 relative): a level floor under gravity, nothing to
    slide down."""
    held = move & (np.einsum("ij,ij->i", v, v) <= REST_SPEED * REST_SPEED)
    if group.shapes is not None:
        held &= ~group.shapes.shaped()
    if group.system.penalty is not None:  # a penalty body rests on its springs: it steps
        held &= ~group.system.penalty.body
    if not held.any() or not group.colliders:
        return np.zeros(len(x), dtype=bool)
    idx = np.flatnonzero(held)
    acc = a[idx]
    g = np.sqrt(np.einsum("ij,ij->i", acc, acc))
    x0 = x[idx]
    x1 = x0 + (step * step) * acc
    supported = np.zeros(idx.size, dtype=bool)
    radius = group.system.props.radius[idx]
    for col in group.colliders:
        hits = col.sweep(x0, x1, radius)
        supported |= hits.hit & (np.einsum("ij,ij->i", hits.normal, acc) <= -(1.0 - 1e-9) * g) & (g > 0)
    out = np.zeros(len(x), dtype=bool)
    out[idx[supported]] = True
    return out


def coast(group: Group, integrator: Integrator, ctx: StepContext, t0: float, t1: float, step: float, guard: Guard, recorder: "Recorder") -> int:
    """Stage coast: advance a body group by the steps ahead in which nothing can happen
    but free flight, all at once; returns how many (0: take the next step normally).

    It applies when D's velocity part is a constant acceleration a (System.
    constant_acceleration: uniform gravity only) and nothing spins (|w| <= REST_SPIN, and nothing
    in D makes it spin), for a fixed-step integrator, on whole steps of the fixed grid
    t0 + k step, before the next body's start time. Then k steps of the integrator from
    (x, v) are exactly v_k = v + k h a and x_k = x + k h v + c(k) h^2 a, with the
    integrator's c(k) (Integrator.ballistic: k^2/2 for midpoint, Heun and RK4; k(k-1)/2
    for explicit Euler; k(k+1)/2 for semi-implicit Euler); orientations stay. The
    trajectory of COAST_STEPS steps is swept against every collider and between body
    pairs (the bounding spheres, as the collide stage's broad phase); the steps before
    the first with a possible contact, and with a finite state within the guard's energy
    bound, are recorded. The same arithmetic in a different order: positions differ from
    stepping by rounding only (1e-16 relative per step, not accumulated).

    A body at rest on a level support (`resting`) is held where it is, in contact, through
    the coast: what the collide stage does to it each step (the support impulse cancels
    what gravity added, no slip, so no friction) is to leave it there; so one ball at rest
    does not stop the others from coasting. Anything that comes near it ends the coast."""
    system = group.system
    c = integrator.ballistic
    if c is None or integrator.adaptive or group.record_stride != 1 or not system.props.names or group.kinematic or group.joints is not None:
        return 0
    a = system.constant_acceleration()
    s = system.unpack(group.X)
    if a is None or (system.rotating and np.abs(s.w).max(initial=0.0) > REST_SPIN):
        return 0
    t_end, K = _coast_window(ctx, system.props.start, t0, t1, step)
    if K == 0:
        return 0
    move = system.moving()
    held = resting(group, s.x, s.v, move, a, step)
    fly = move & ~held
    acc = np.where(fly[:, None], a, 0.0)
    k = np.arange(K + 1, dtype=np.float64)[:, None, None]
    xs = s.x[None] + (k * step) * np.where(fly[:, None], s.v, 0.0)[None] + (c(k) * step * step) * acc[None]
    vs = np.where(held[:, None], 0.0, s.v)[None] + (k * step) * acc[None]
    # the first step with a possible contact, or past the guard's bound, ends the coast before it
    first = _first_contact(group, xs, fly, move, K)
    kinetic, potential = _energies(system, xs, vs, move)
    total = kinetic.sum(axis=1) + potential.sum(axis=1)
    bad = ~(np.isfinite(total) & np.isfinite(xs[1:]).all(axis=(1, 2)) & (total <= guard.bound()))
    if bad.any():
        first = min(first, int(np.argmax(bad)))
    if first == 0:
        return 0
    K = first
    if group.shapes is not None and ((group.shapes.shaped() & move).any() or group.pairs[0].size):
        for _ in range(min(K, 2)):  # what K contact-free collide stages leave of the warm start
            group.shapes.begin_step()
    q = s.q.copy() if system.rotating else None
    w = s.w.copy() if system.rotating else None
    recorder.record_many(t_end[:K], xs[1 : K + 1], vs[1 : K + 1], q, kinetic[:K], potential[:K], held)
    group.X = system.pack(xs[K], vs[K], q, w)
    return K


def _coast_window(ctx: StepContext, start: np.ndarray, t0: float, t1: float, step: float) -> tuple[np.ndarray, int]:
    """Where each of the next COAST_STEPS grid steps ends (t0 + k step), and how many of
    them are whole steps before t1 and before the next body's start time (the active set
    stays as it is)."""
    index = ctx.index + np.arange(1, COAST_STEPS + 1)
    t_end = t0 + index * step  # where each step ends, on the grid
    starts = np.concatenate(([ctx.t], t_end[:-1]))
    ok = (t1 - starts >= step) & (starts < t1 - 1e-9 * max(1.0, abs(t1)))
    later = start[start > ctx.t + 1e-12]
    if later.size:
        ok &= starts + 1e-12 < later.min()  # the active set stays as it is
    return t_end, int(np.argmin(ok)) if not ok.all() else ok.size


def _first_contact(group: Group, xs: np.ndarray, fly: np.ndarray, move: np.ndarray, K: int) -> int:
    """The first of the K coast steps (states xs [K + 1, n, 3]) with a possible contact,
    K if none: each step's segment swept against every collider (held bodies lie on their
    support: only the bodies in flight, `fly`, are swept) and between body pairs (their
    bounding spheres, as the collide stage's broad phase)."""
    p = group.system.props
    n = group.system.n
    x0, x1 = xs[:-1].reshape(-1, 3), xs[1:].reshape(-1, 3)
    moving = np.tile(fly, K)
    first = K
    for col in group.colliders:
        hit = col.sweep(x0, x1, np.tile(p.radius, K)).hit & moving
        if hit.any():
            first = min(first, int(np.argmax(hit)) // n)
    i, j = group.pairs
    if i.size:
        inv = np.where(move, p.inv_mass, 0.0)
        rel = xs[:, i] - xs[:, j]
        hit = _sweep_spheres(rel[:-1].reshape(-1, 3), rel[1:].reshape(-1, 3), np.tile(p.radius[i] + p.radius[j], K)).hit
        hit &= np.tile(inv[i] + inv[j] > 0, K)
        if hit.any():
            first = min(first, int(np.argmax(hit)) // i.size)
    return first


def _energies(system: System, xs: np.ndarray, vs: np.ndarray, move: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic and potential energy [K, n] of each coast state after the first (no spin:
    kinetic 1/2 m v^2; gravity only: no shared terms)."""
    p = system.props
    kinetic = np.where(move, 0.5 * p.mass * np.einsum("kij,kij->ki", vs[1:], vs[1:]), 0.0)
    potential = np.where(move, -p.mass * ((xs[1:] - system.x_ref) @ system.env.gravity), 0.0)
    return kinetic, potential


def run_group(group: Group, integrator: Integrator, t0: float, t1: float, step: float, iterations: int, guard: Guard,
              on_progress: Callable[[float, float, float], None] | None = None, max_steps: int | None = None) -> Track:
    """Advance a group from t0 to t1 through the named stages; returns its Track.
    `on_progress(t, t0, t1)` is called every 64 steps and at the end. An adaptive
    integrator may take at most `max_steps` steps (None: no bound); past that, a
    SimulationError says where it was and what made it step down."""
    system = group.system
    g_mag = float(np.linalg.norm(system.env.gravity))
    recorder = Recorder(group, int(math.ceil((t1 - t0) / step / group.record_stride)) + 2)
    pending = np.zeros(system.n, dtype=bool)  # contacts since the last record
    group.activate(group, StepContext(t0, 0.0, math.inf, 0))
    energy = system.energy(group.X)
    guard.e_in = float(energy[0].sum() + energy[1].sum() + energy[2])
    recorder.record(t0, group.X, pending, energy)
    t, index, h_next = t0, 0, step
    end = t1 - 1e-9 * max(1.0, abs(t1))
    wait = skip = 0  # after a coast that could not start, the next tries come later and later
    while t < end:
        h = min(h_next, step, t1 - t)
        ctx = StepContext(t, h, 1.0 / h, index)
        activate(group, ctx, guard)
        if skip:
            skip -= 1
        else:
            done = coast(group, integrator, ctx, t0, t1, step, guard, recorder)
            if done:
                wait = 0
                if on_progress is not None and (index + done) // 64 > index // 64:
                    on_progress(t0 + (index + done) * step, t0, t1)
                t, index = t0 + (index + done) * step, index + done
                continue
            wait = skip = min(2 * wait + 1, 64)
        if max_steps is not None and integrator.adaptive and index >= max_steps:
            raise SimulationError(
                f"{integrator.name} took its budget of {max_steps} steps (dynamics.rk45_max_steps) by t = {t:.6g} s of {t0:g}..{t1:g} s, its last "
                f"step {h:.3g} s (the scene's step {step:g} s): a stiff force, such as a penalty contact's spring, makes it step down; "
                "soften the contact (a longer penalty contact_time), loosen rtol/atol, raise the budget or use a fixed-step integrator")
        X = group.X
        X1, ctx, h_next = integrate(group, integrator, ctx, t0, step)
        contact, found = collide(group, X, X1, ctx, iterations, g_mag)
        if group.joints is not None:
            hold_joints(group, X1, ctx)
        if system.penalty is not None:
            advance_springs(group, X1, ctx)
        recorder.impacts.extend(found)
        pending |= contact
        energy = guard_step(group, guard, X1, ctx)
        group.X = X1
        t, index = ctx.t_next, index + 1
        if index % group.record_stride == 0 or t >= end:
            recorder.record(t, X1, pending, energy)
            pending[:] = False
        if on_progress is not None and index % 64 == 0:
            on_progress(t, t0, t1)
    if on_progress is not None:
        on_progress(t, t0, t1)
    return recorder.track()
