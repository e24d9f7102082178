"""Scene format v1: dynamics. Per-body `motion: {type: dynamics}` blocks, the scene-wide
`dynamics:` simulation settings (integrator, step, forces, springs, fluids) and particle
emitters. SI units: kg, m, s; angles in degrees (angular velocity in degrees/s)."""

# No `from __future__ import annotations` in the schema modules: pydantic would compile and
# evaluate every field's annotation string when each model class is made, about 0.03 s of
# every process that loads a scene (issue 28, docs/ci-sharding.md).

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .types import FiniteFloat, Model, NonNegative, Positive, Vec3

Integrator = Literal["euler", "semi-implicit-euler", "midpoint", "heun", "rk4", "rk45"]


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
    start: FiniteFloat = 0.0  # seconds after the first frame: held at its transform before then


class Spring(Model):
    """Hooke spring between two bodies (by object name): F = -k (|d| - rest) d/|d| - c v_rel."""

    a: str
    b: str
    stiffness: Positive  # N/m
    damping: NonNegative = 0.0  # N s/m
    rest_length: NonNegative | None = None  # metres; default: the initial distance


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
    contact_iterations: Annotated[int, Field(ge=1, le=100)] = 8
    energy_growth_limit: Annotated[float, Field(gt=1)] = 10.0  # blow-up guard factor


class ParticleEmitter(Model):
    """Spawns particles at `rate` per second from `position` (a point or a box of `size`)
    with speed `speed` +- `speed_spread` inside a cone of `spread` degrees about
    `direction`; each lives `lifetime` seconds. Seeded: the same seed, the same particles."""

    rate: Positive = 100.0
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
    start: FiniteFloat = 0.0  # seconds after the first frame (the dynamics clock)
    stop: FiniteFloat | None = None  # seconds after the first frame

    @model_validator(mode="after")
    def _window(self) -> "ParticleEmitter":
        if self.stop is not None and self.stop <= self.start:
            raise ValueError(f"stop ({self.stop}) must be after start ({self.start})")
        return self
