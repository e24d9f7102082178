"""Scene format v1: dynamics. Per-body `motion: {type: dynamics}` blocks, the scene-wide
`dynamics:` simulation settings (integrator, step, forces, springs, fluids) and particle
emitters. SI units: kg, m, s; angles in degrees (angular velocity in degrees/s)."""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

import math
from typing import Annotated, Any, Literal, NamedTuple

from pydantic import Field, model_validator

from .types import FiniteFloat, Model, NonNegative, Positive, Vec3

Integrator = Literal["euler", "semi-implicit-euler", "midpoint", "heun", "rk4", "rk45"]
Contact = Literal["impulse", "penalty"]
DEFAULT_CONTACT_TIME = 0.01  # s: a penalty contact's duration when neither stiffness nor contact_time is given
MIN_STEPS_PER_CONTACT = 10  # fewer fixed steps than this over one penalty contact: a warning


class Penalty(Model):
    """Penalty-force contact (`contact: penalty`): a spring-damper along the contact normal,
    F = k depth + c d(depth)/dt per contact point, with Coulomb friction from that force.
    Give `stiffness` (N/m; `damping` N s/m, default from the restitution), or a
    `restitution` and `contact_time` (s) from which k and c follow for the body's mass
    (linear spring-damper: e = exp(-zeta pi / sqrt(1 - zeta^2)), contact time pi / omega_d).
    `restitution` defaults to the body's own."""

    stiffness: Positive | None = None  # N/m per contact point
    damping: NonNegative | None = None  # N s/m
    restitution: Annotated[float, Field(ge=0, le=1)] | None = None
    contact_time: Positive | None = None  # s

    @model_validator(mode="after")
    def _one_way(self) -> "Penalty":
        if self.damping is not None and self.stiffness is None:
            raise ValueError("damping needs a stiffness (or give restitution and contact_time instead)")
        if self.stiffness is not None and self.contact_time is not None:
            raise ValueError("give either stiffness (and damping) or contact_time, not both: the contact time follows from the stiffness and mass")
        return self


class PenaltyParameters(NamedTuple):
    """One body's penalty contact against a rigid surface: k (N/m), c (N s/m), zeta (the
    damping ratio c / (2 sqrt(k m))) and omega0 (rad/s, sqrt(k / m))."""

    k: float
    c: float
    zeta: float
    omega0: float

    @property
    def contact_time(self) -> float:
        """pi / omega_d (s), omega_d = omega0 sqrt(1 - zeta^2); inf when zeta >= 1 (no rebound)."""
        return math.pi / (self.omega0 * math.sqrt(1.0 - self.zeta**2)) if self.zeta < 1.0 else math.inf

    @property
    def restitution(self) -> float:
        """exp(-zeta pi / sqrt(1 - zeta^2)); 0 when zeta >= 1."""
        return math.exp(-self.zeta * math.pi / math.sqrt(1.0 - self.zeta**2)) if self.zeta < 1.0 else 0.0


def damping_ratio(restitution: float) -> float:
    """zeta of the linear spring-damper whose restitution is e: from e = exp(-zeta pi /
    sqrt(1 - zeta^2)), zeta = -ln e / sqrt(pi^2 + ln^2 e); e = 0 -> 1 (critical)."""
    if restitution <= 0.0:
        return 1.0
    ln = math.log(restitution)
    return -ln / math.sqrt(math.pi**2 + ln * ln)


def penalty_parameters(spec: Penalty, mass: float, restitution: float) -> PenaltyParameters:
    """A body's k, c from its `penalty` block, its mass (kg) and its own restitution (used
    when the block gives none). From a contact time T: omega_d = pi / T, omega0 = omega_d /
    sqrt(1 - zeta^2), k = m omega0^2, c = 2 zeta m omega0 (zeta = 1: omega0 = pi / T)."""
    e = spec.restitution if spec.restitution is not None else restitution
    if spec.stiffness is not None:
        k = spec.stiffness
        omega0 = math.sqrt(k / mass)
        if spec.damping is not None:
            return PenaltyParameters(k, spec.damping, spec.damping / (2.0 * math.sqrt(k * mass)), omega0)
        zeta = damping_ratio(e)
        return PenaltyParameters(k, 2.0 * zeta * math.sqrt(k * mass), zeta, omega0)
    zeta = damping_ratio(e)
    t_c = spec.contact_time if spec.contact_time is not None else DEFAULT_CONTACT_TIME
    omega0 = math.pi / t_c / (math.sqrt(1.0 - zeta * zeta) if zeta < 1.0 else 1.0)
    return PenaltyParameters(mass * omega0 * omega0, 2.0 * zeta * mass * omega0, zeta, omega0)


class Drag(Model):
    """Rayleigh drag 0.5 rho Cd A |v|^2 against v; `area` defaults to the shape's
    cross-section; `linear` adds -linear * v (N s/m)."""

    cd: NonNegative = 0.47
    area: Positive | None = None
    linear: NonNegative = 0.0


class DynamicsMotion(Model):
    """`motion: {type: dynamics}`: the object is a simulated body (rigid, or a particle
    that does not rotate) with its mass, initial velocities, contact material and drag;
    `pinned` holds it still with infinite mass; `start` holds it until then (seconds after
    the shot's first frame: the dynamics clock, docs/dynamics.md)."""

    type: Literal["dynamics"]
    body: Literal["particle", "rigid"] = "rigid"
    mass: Positive = 1.0  # kg
    velocity: Vec3 = (0.0, 0.0, 0.0)  # m/s, initial
    angular_velocity: Vec3 = (0.0, 0.0, 0.0)  # degrees/s, initial, world axes
    restitution: Annotated[float, Field(ge=0, le=1)] = 0.5
    friction: NonNegative = 0.3  # kinetic coefficient
    static_friction: NonNegative | None = None
    drag: Drag | None = None
    pinned: bool = False  # infinite mass: forces and impulses do not move it
    start: Annotated[FiniteFloat, Field(json_schema_extra={"unit": "s"}, description="when the body starts to move, in seconds after the first frame (the dynamics clock: 0 at the timeline's first frame, whatever its number); held at its transform before then")] = 0.0
    contact: Contact | None = None  # impulse | penalty; default: the simulation's `dynamics.contact`
    penalty: Penalty | None = None  # this body's penalty contact; default: `dynamics.penalty`


class Spring(Model):
    """Hooke spring between two bodies (by object name): F = -k (|d| - rest) d/|d| - c v_rel."""

    a: str
    b: str
    stiffness: Positive  # N/m
    damping: NonNegative = 0.0  # N s/m
    rest_length: NonNegative | None = None  # metres; default: the initial distance


MAX_JOINTS = 10_000  # joints in one scene (each a row of the vectorised solver)


class Joint(Model):
    """A joint between body `a` and body `b` (or the world: `b` omitted or "world"), solved
    as a constraint after each step (docs/dynamics.md, Joints): `pin` (ball and socket at
    `anchor`), `hinge` (at `anchor`, turning about `axis` only, optionally within `limits`
    in degrees), `distance` (a rigid rod) and `rope` (at most `length`, slack below it)
    between `anchor_a` on a and `anchor` on b. Points and axes are world coordinates at
    the bodies' start pose; each then moves with its body. A joint whose force passes
    `break_force` (N) breaks."""

    type: Literal["pin", "hinge", "distance", "rope"]
    a: str
    b: str = "world"
    anchor: Vec3 | None = None  # m: the pivot (pin, hinge), or the end on b; default b's centre
    anchor_a: Vec3 | None = None  # m: a rod's or rope's end on a; default a's centre
    axis: Vec3 | None = None  # hinge axis (world, at the start pose)
    limits: tuple[FiniteFloat, FiniteFloat] | None = None  # degrees: a hinge's angle range from its start pose
    length: NonNegative | None = None  # m: a rod's or rope's length; default the anchors' initial distance
    break_force: Positive | None = None  # N

    @model_validator(mode="after")
    def _consistent(self) -> "Joint":
        if self.a == self.b:
            raise ValueError(f"a joint needs two different bodies (a and b are both '{self.a}')")
        if self.type == "hinge":
            if self.axis is None:
                raise ValueError("a hinge needs an axis")
            if math.sqrt(sum(c * c for c in self.axis)) < 1e-9:
                raise ValueError(f"a hinge axis must not be zero (got {list(self.axis)})")
        elif self.axis is not None or self.limits is not None:
            raise ValueError(f"axis and limits are for a hinge, not a {self.type}")
        if self.limits is not None and not (-360.0 <= self.limits[0] <= self.limits[1] <= 360.0):
            raise ValueError(f"limits must be [low, high] degrees with -360 <= low <= high <= 360 (got {list(self.limits)})")
        if self.type in ("pin", "hinge"):
            if self.length is not None or self.anchor_a is not None:
                raise ValueError(f"length and anchor_a are for a distance or rope joint; a {self.type} joins its bodies at `anchor`")
            if self.b == "world" and self.anchor is None:
                raise ValueError(f"a {self.type} to the world needs an anchor (the pivot, world coordinates)")
        elif self.b == "world" and self.anchor is None:
            raise ValueError(f"a {self.type} to the world needs an anchor (where it is tied, world coordinates)")
        return self


class Fluid(Model):
    """A fluid half-space below `level` along +up (the sea): buoyancy rho V_sub g, and
    the fluid's drag on bodies inside it."""

    type: Literal["half-space"] = "half-space"
    level: FiniteFloat = 0.0
    density: Positive = 1025.0  # kg/m^3 (sea water)
    drag_cd: NonNegative = 0.47


class NewtonianGravity(Model):
    """F = G m_i m_j / r^2 between every pair of dynamic bodies (O(n^2))."""

    G: Positive = 6.674e-11
    softening: NonNegative = 1e-3  # metres, avoids the singularity at r = 0


class DynamicsSettings(Model):
    """The scene-wide `dynamics:` block: integrator and fixed step (rk45 adapts within it,
    to rtol/atol), gravity, air, wind and force fields, Newtonian gravity, fluids,
    springs, contact iterations and the blow-up guard (docs/dynamics.md)."""

    integrator: Integrator = "rk4"
    step: Annotated[float, Field(gt=0, le=1)] = 1.0 / 480.0  # seconds
    rtol: Positive = 1e-6  # rk45
    atol: Positive = 1e-9  # rk45
    gravity: Vec3 = (0.0, -9.81, 0.0)
    air_density: NonNegative = 1.225  # kg/m^3
    wind: tuple[str, str, str] | None = None  # m/s, expressions in t, x, y, z
    force_field: tuple[str, str, str] | None = None  # N/kg, expressions in t, x, y, z
    newtonian_gravity: NewtonianGravity | None = None
    fluids: list[Fluid] = []
    springs: list[Spring] = []
    joints: Annotated[list[Joint], Field(max_length=MAX_JOINTS)] = []  # pins, hinges, rods, ropes
    contact_iterations: Annotated[int, Field(ge=1, le=100)] = 8
    contact: Contact = "impulse"  # every body's contact model (a body's own `contact` wins)
    penalty: Penalty = Penalty.default()  # penalty contacts of bodies that give none of their own
    rk45_max_steps: Annotated[int, Field(ge=1)] = 1_000_000  # rk45's budget of steps over the run
    energy_growth_limit: Annotated[float, Field(gt=1)] = 10.0  # blow-up guard factor


class ParticleEmitter(Model):
    """Spawns particles at `rate` per second from `position` (a point or a box of `size`)
    with speed `speed` +- `speed_spread` inside a cone of `spread` degrees about
    `direction`; each lives `lifetime` seconds. Seeded: the same seed, the same particles."""

    rate: Annotated[Positive, Field(json_schema_extra={"unit": "particles/s"})] = 100.0
    lifetime: Positive = 2.0
    position: Vec3 = (0.0, 0.0, 0.0)
    size: Vec3 = (0.0, 0.0, 0.0)
    direction: Vec3 = (0.0, 1.0, 0.0)
    speed: NonNegative = 5.0
    speed_spread: NonNegative = 0.0
    spread: Annotated[float, Field(ge=0, le=180)] = 15.0
    mass: Positive = 0.001
    restitution: Annotated[float, Field(ge=0, le=1)] = 0.3
    friction: NonNegative = 0.3  # kinetic and static coefficient against colliders
    drag: Drag | None = None
    seed: int = 0
    max_count: Annotated[int, Field(ge=1, le=10_000_000)] = 100_000
    start: Annotated[FiniteFloat, Field(json_schema_extra={"unit": "s"}, description="when emission starts, in seconds after the first frame (the dynamics clock: 0 at the timeline's first frame, whatever its number)")] = 0.0
    stop: Annotated[FiniteFloat | None, Field(json_schema_extra={"unit": "s"}, description="when emission stops, in seconds after the first frame; null: the end of the shot")] = None

    @model_validator(mode="after")
    def _window(self) -> "ParticleEmitter":
        if self.stop is not None and self.stop <= self.start:
            raise ValueError(f"stop ({self.stop}) must be after start ({self.start})")
        return self


# --- the step's stability for a penalty contact ---------------------------------------------
# One step of an integrator on the contact's linear oscillator x'' = -w^2 x - 2 zeta w x'
# multiplies the state by R(z), z = h lambda, lambda = w (-zeta +- i sqrt(1 - zeta^2)):
# the method's stability polynomial (Runge-Kutta) or, for semi-implicit Euler, the 2 x 2
# matrix [[1 - y^2, y (1 - 2 zeta y)], [-y, 1 - 2 zeta y]] on (w x, v), y = h w. Stable
# while the spectral radius is <= 1.
_POLYNOMIALS = {
    "euler": (1.0, 1.0),
    "midpoint": (1.0, 1.0, 1 / 2),
    "heun": (1.0, 1.0, 1 / 2),
    "rk4": (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24),
    "rk45": (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 600),  # Dormand-Prince 5th order solution
}


def amplification(integrator: str, zeta: float, y: Any) -> Any:
    """Spectral radius of one step of `integrator` on the contact oscillator, y = h omega0
    (a number or an array)."""
    import numpy as np

    y = np.asarray(y, dtype=np.float64)
    root = np.sqrt(complex(1.0 - zeta * zeta))
    lams = (-zeta + 1j * root, -zeta - 1j * root)
    if integrator == "semi-implicit-euler":
        a, b, c, d = 1.0 - y * y, y * (1.0 - 2.0 * zeta * y), -y, 1.0 - 2.0 * zeta * y
        half = 0.5 * (a + d)
        disc = np.sqrt((half * half - (a * d - b * c)).astype(complex))
        return np.maximum(np.abs(half + disc), np.abs(half - disc))
    coeffs = _POLYNOMIALS[integrator]
    out = np.zeros(y.shape)
    for lam in lams:
        z = y * lam
        out = np.maximum(out, np.abs(sum(cf * z**k for k, cf in enumerate(coeffs))))
    return out


def stability_limit(integrator: str, zeta: float) -> float:
    """The largest y = h omega0 up to which every step of `integrator` is stable on the
    contact oscillator of damping ratio zeta (0: unstable at any step: explicit Euler,
    midpoint and Heun on an undamped spring)."""
    import numpy as np

    ys = np.linspace(0.0, 8.0, 8001)[1:]
    bad = amplification(integrator, zeta, ys) > 1.0 + 1e-14
    if not bad.any():
        return float(ys[-1])
    k = int(np.argmax(bad))
    if k == 0:
        return 0.0
    lo, hi = float(ys[k - 1]), float(ys[k])
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if amplification(integrator, zeta, mid) <= 1.0 + 1e-14 else (lo, mid)
    return lo


def penalty_bodies(scene: Any) -> list[tuple[int, Any, PenaltyParameters]]:
    """(object index, object, its penalty parameters) of every dynamics body with penalty
    contacts (its own `contact`, else the simulation's)."""
    d = scene.dynamics
    out = []
    for i, obj in enumerate(scene.objects):
        m = obj.motion
        if m.type != "dynamics" or m.pinned or (m.contact or d.contact) != "penalty":  # (a pinned body never moves)
            continue
        out.append((i, obj, penalty_parameters(m.penalty or d.penalty, m.mass, m.restitution)))
    return out


def _penalty_loc(scene: Any, i: int) -> tuple:
    m = scene.objects[i].motion
    if m.penalty is not None:
        return ("objects", i, "motion", "penalty")
    return ("objects", i, "motion", "contact") if m.contact is not None else ("dynamics", "contact")


def _describe(name: str, p: PenaltyParameters, mass: float) -> str:
    during = f"contact time {1e3 * p.contact_time:.4g} ms" if p.zeta < 1.0 else "no rebound (zeta >= 1)"
    return f"'{name}': k = {p.k:.4g} N/m, c = {p.c:.4g} N s/m, m = {mass:g} kg: sqrt(m/k) = {1e3 / p.omega0:.4g} ms, zeta = {p.zeta:.3g}, {during}"


def contact_modes(obj: Any) -> list[tuple[float, str]]:
    """(s^2, what) for the contact modes of a penalty body resting on a plane: each mode's
    angular frequency is s sqrt(k/m) and its damping ratio s zeta (the contact points'
    dampers are their springs times c/k, so the modes of K are those of C). Spheres: one
    point (s^2 = 1); boxes on a face: 4 corners (vertical 4, rocking 12 a^2/(a^2 + b^2) for
    half extents a along the rocking lever, b along the normal); capsules on their side: 2
    cap spheres (2, and rocking 2 a^2 m / I); cylinders on a cap: 8 rim points (8, and
    4 r^2 m / I). Meshes: 1 here (their hull is read by the dynamics stage; the blow-up
    guard catches a step too long for their modes)."""
    import numpy as np

    from ..geometry import shape_geometry

    m = obj.motion.mass
    entry = shape_geometry(obj.shape)
    if obj.shape not in ("cube", "capsule", "cylinder"):
        return [(1.0, "one point")]
    meas = entry.measure(obj, np.asarray(obj.transform.scale, dtype=np.float64), None)
    inertia = entry.inertia(m, meas.dims)
    d = meas.dims
    if obj.shape == "cube":
        half = np.array([d["sx"], d["sy"], d["sz"]]) / 2
        out = [(4.0, "4 corners, vertical")]
        for normal in range(3):
            for lever in range(3):
                if lever != normal:
                    a, b = half[lever], half[normal]
                    out.append((12 * a * a / (a * a + b * b), "4 corners, rocking"))
        return out
    if obj.shape == "capsule":
        a = d["height"] / 2
        return [(2.0, "2 caps, vertical"), (2 * a * a * m / inertia[0], "2 caps, rocking")]
    r, h = d["radius"], d["height"]
    return [(8.0, "8 rim points, vertical"), (4 * r * r * m / inertia[0], "8 rim points, rocking"), (2 * (h / 2) ** 2 * m / inertia[0], "on its side, rocking")]


def penalty_problems(scene: Any) -> list[tuple[tuple, str]]:
    """(YAML path, message) for each penalty body whose contact the fixed step cannot
    integrate stably: for each of its contact modes (`contact_modes`: frequency s omega0,
    damping ratio s zeta), h s omega0 past the integrator's stability limit for that
    damping ratio (`stability_limit`). rk45 adapts its step and is never refused here (its
    step budget is checked while it runs)."""
    d = scene.dynamics
    if d.integrator == "rk45":
        return []
    out = []
    for i, obj, p in penalty_bodies(scene):
        worst = None
        for s2, what in contact_modes(obj):
            s = math.sqrt(s2)
            limit = stability_limit(d.integrator, s * p.zeta)
            y = d.step * p.omega0 * s
            if y > limit and (worst is None or y / max(limit, 1e-300) > worst[0]):
                worst = (y / max(limit, 1e-300), s, limit, what)
        if worst is None:
            continue
        _, s, limit, what = worst
        mode = "" if s == 1.0 else f" (its stiffest contact mode, {what}: omega = {s:.3g} sqrt(k/m), zeta = {s * p.zeta:.3g})"
        if limit == 0.0:
            bound = f"{d.integrator} is unstable on this contact at any step{mode} (an undamped or barely damped spring gains energy every step)"
            fix = "use semi-implicit-euler or rk4, or a lower restitution"
        else:
            h_max = limit / (s * p.omega0)
            bound = f"the stability bound of {d.integrator} for this contact{mode} is h < {1e3 * h_max:.4g} ms, the step is {1e3 * d.step:.4g} ms"
            others = " or ".join(x for x in ("rk4", "rk45") if x != d.integrator)
            fix = f"use dynamics.step <= {h_max / 2:.3g} s, {others}, or a softer contact (a longer contact_time)"
        out.append((_penalty_loc(scene, i), f"penalty contact of {_describe(obj.name, p, obj.motion.mass)}: {bound}; {fix}"))
    return out


def penalty_warnings(scene: Any) -> list[str]:
    """Penalty contacts the fixed step resolves with fewer than MIN_STEPS_PER_CONTACT steps
    (stable, but the rebound and the depth are off by a visible amount)."""
    d = scene.dynamics
    if d.integrator == "rk45":
        return []
    out = []
    for i, obj, p in penalty_bodies(scene):
        span = p.contact_time if p.zeta < 1.0 else math.pi / p.omega0  # (no rebound: the time scale pi / omega0)
        steps = span / d.step
        if steps < MIN_STEPS_PER_CONTACT and d.step * p.omega0 <= stability_limit(d.integrator, p.zeta):
            out.append(f"objects[{i}].motion: penalty contact of {_describe(obj.name, p, obj.motion.mass)} lasts {steps:.3g} steps of "
                       f"{1e3 * d.step:.4g} ms: its rebound and depth are under-resolved (dynamics.step <= {span / MIN_STEPS_PER_CONTACT:.3g} s "
                       f"gives {MIN_STEPS_PER_CONTACT} steps)")
    return out
