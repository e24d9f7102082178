"""System state and its derivative D(t, X), vectorised over bodies.

X is one flat float64 vector: positions x [n, 3], then (rigid groups) orientations
q [n, 4], then velocities v [n, 3], then (rigid groups) angular velocities w [n, 3]
(world frame, rad/s). Everything before `split` is "position-like" (its rate depends on
the velocities), everything after is "velocity-like" (its rate depends on the forces):
semi-implicit Euler uses that split.

D(t, X) = (v, 1/2 (0, w) q, F(t, x, v) / m, I^-1 (tau - w x I w)), computed in one pass
over arrays; pinned bodies (inverse mass 0) and bodies not yet started have D = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from . import forces
from ..motion.pose import quat_normalize
from .rigid import angular_acceleration, isotropic, quat_rate

if TYPE_CHECKING:
    from .penalty import PenaltySet


@dataclass
class BodyProps:
    """Cold per-body data (constant during a run), one entry per body, SI units."""

    names: list[str]
    mass: np.ndarray  # kg
    inv_mass: np.ndarray  # 1/kg, 0 for pinned bodies
    radius: np.ndarray  # m, collision radius (bounding sphere)
    radius_eq: np.ndarray  # m, radius of the sphere of the body's volume (buoyancy)
    area: np.ndarray  # m^2, drag reference area
    cd: np.ndarray  # Rayleigh drag coefficient in air (0: none)
    linear: np.ndarray  # N s/m, linear drag
    restitution: np.ndarray
    friction: np.ndarray  # kinetic coefficient
    static_friction: np.ndarray
    start: np.ndarray  # s, held still before this time
    inertia: np.ndarray  # [n, 3] principal moments (kg m^2), body axes
    inv_inertia: np.ndarray  # [n, 3], 0 for pinned and point bodies

    @property
    def count(self) -> int:
        """Number of bodies."""
        return int(self.mass.size)

    def take(self, index: np.ndarray) -> "BodyProps":
        """The props of a subset of bodies (particle groups grow by activating slices)."""
        return BodyProps(
            names=[self.names[i] for i in np.asarray(index)] if self.names else [],
            **{k: getattr(self, k)[index] for k in _ARRAY_FIELDS},
        )


_ARRAY_FIELDS = ("mass", "inv_mass", "radius", "radius_eq", "area", "cd", "linear", "restitution", "friction", "static_friction", "start", "inertia", "inv_inertia")


@dataclass
class Environment:
    """Scene-wide forces: gravity (m/s^2), air density (kg/m^3), wind and force field
    (parsed expressions or None), fluids, springs, Newtonian gravity (G, softening) or None."""

    gravity: np.ndarray
    air_density: float = 1.225
    wind: tuple[object, object, object] | None = None
    force_field: tuple[object, object, object] | None = None
    fluids: list[forces.HalfSpaceFluid] = field(default_factory=list)
    springs: forces.SpringSet | None = None
    newtonian: tuple[float, float] | None = None


@dataclass
class State:
    """Views into a flat state vector (no copies)."""

    x: np.ndarray
    v: np.ndarray
    q: np.ndarray | None
    w: np.ndarray | None


class System:
    """A group of bodies under one Environment: the D(t, X) an integrator advances.

    D takes the step's dt (drag uses it so it never reverses a velocity within a step;
    step.StepDynamics binds it per step); `active` marks bodies that move this step
    (started, alive, not pinned)."""

    def __init__(self, props: BodyProps, env: Environment, rotating: bool) -> None:
        self.props = props
        self.env = env
        self.rotating = rotating
        self.n = props.count
        self.split = self.n * (7 if rotating else 3)
        self.size = self.n * (13 if rotating else 6)
        self.active = np.ones(self.n, dtype=bool)
        # constant for the run (props and environment do not change): computed once
        self._gravity = forces.gravity(props.mass, env.gravity)
        self._gravity_acc = self._gravity * props.inv_mass[:, None]
        self._air_drag = bool(np.any(props.cd > 0) or np.any(props.linear > 0))
        # gravity and air drag only (what big particle systems have): D's accelerations in
        # a few passes over memory, from rates per unit mass computed once (see acceleration)
        self._plain = not (env.fluids or env.force_field is not None or env.wind is not None or (env.springs is not None and env.springs.count)
                           or (env.newtonian is not None and self.n > 1))
        self._drag_rate = (0.5 * env.air_density * props.cd * props.area * props.inv_mass,
                           props.linear * props.inv_mass if props.linear.any() else None)
        self._isotropic = rotating and props.count > 0 and isotropic(props.inertia)
        self._free = props.inv_mass > 0  # not pinned (pinned: inverse mass 0)
        self.x_ref = np.zeros((self.n, 3))  # where gravity's potential is zero
        self.penalty: "PenaltySet | None" = None  # penalty-force contacts (penalty.py), part of D
        if env.newtonian is not None and self.n > forces.NBODY_LIMIT:
            from ..errors import SimulationError

            raise SimulationError(f"newtonian_gravity is O(n^2) and limited to {forces.NBODY_LIMIT} bodies; this scene has {self.n}")

    @property
    def active(self) -> np.ndarray:
        """Bodies that move this step (started, alive); set by the activate stage."""
        return self._active

    @active.setter
    def active(self, value: np.ndarray) -> None:
        """Set by the activate stage each step."""
        self._active = value
        self._moving: np.ndarray | None = None

    # --- layout ---------------------------------------------------------------------------

    def unpack(self, X: np.ndarray) -> State:
        """Views of x, v (and q, w for rigid groups) into the flat state X."""
        n = self.n
        if self.rotating:
            return State(X[: 3 * n].reshape(n, 3), X[7 * n : 10 * n].reshape(n, 3), X[3 * n : 7 * n].reshape(n, 4), X[10 * n :].reshape(n, 3))
        return State(X[: 3 * n].reshape(n, 3), X[3 * n :].reshape(n, 3), None, None)

    def pack(self, x: np.ndarray, v: np.ndarray, q: np.ndarray | None = None, w: np.ndarray | None = None) -> np.ndarray:
        """One flat float64 state vector from its parts (see the module docstring)."""
        parts = [x, q, v, w] if self.rotating else [x, v]
        return np.concatenate([np.asarray(p, dtype=np.float64).ravel() for p in parts])

    def normalize(self, X: np.ndarray) -> np.ndarray:
        """Project back onto the state manifold: unit quaternions."""
        if self.rotating and self.n:
            q = X[3 * self.n : 7 * self.n].reshape(self.n, 4)
            norm = np.sqrt(np.einsum("ij,ij->i", q, q))
            if norm.all():  # (the usual case, in two numpy calls; a zero one -> identity)
                q /= norm[:, None]
            else:
                q[:] = quat_normalize(q)
        return X

    # --- forces and D ---------------------------------------------------------------------

    def forces(self, t: float, x: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """Total force on each body (N): gravity, field, drag (air with wind, water; capped
        so it does not reverse a velocity within a step of `dt` s), buoyancy, springs,
        Newtonian gravity."""
        p, env = self.props, self.env
        total = self._gravity.copy()
        if env.force_field is not None:
            total += forces.field_force(p.mass, env.force_field, t, x)
        submerged = np.zeros(self.n)
        for fluid in env.fluids:
            f_b, frac = forces.buoyancy(x, p.radius_eq, fluid, env.gravity)
            total += f_b
            submerged = np.maximum(submerged, frac)
            # water drag on the wetted part of the reference area (the fluid is at rest)
            total += forces.drag(v, p.mass, fluid.density, np.full(self.n, fluid.cd), p.area * frac, np.zeros(self.n), dt)
        if self._air_drag:
            v_rel = v - forces.wind_velocity(env.wind, t, x) if env.wind is not None else v
            total += forces.drag(v_rel, p.mass, env.air_density, p.cd, p.area * (1.0 - submerged), p.linear, dt)
        if env.springs is not None and env.springs.count:
            total += forces.springs(x, v, env.springs)
        if env.newtonian is not None and self.n > 1:
            total += forces.newtonian_gravity(x, p.mass, *env.newtonian)
        return total

    def acceleration(self, t: float, x: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
        """Each body's acceleration [n, 3] (m/s^2): forces / mass, a new array. Under gravity
        and air drag only, a = g - c v with drag's rate c per unit mass (forces.
        drag_coefficient, capped at 1/dt), without forming the forces."""
        if not self._plain:
            acc = self.forces(t, x, v, dt)
            acc *= self.props.inv_mass[:, None]
            return acc
        if not self._air_drag:
            return self._gravity_acc.copy()
        quadratic, linear = self._drag_rate
        rate = forces.drag_coefficient(v, quadratic, linear, 1.0 / dt if dt > 0 else None)
        np.negative(rate, out=rate)
        acc = v * rate[:, None]
        acc += self._gravity_acc
        return acc

    def constant_acceleration(self) -> np.ndarray | None:
        """Each body's acceleration [n, 3] (m/s^2) when D's velocity part does not depend on
        the state or the time (uniform gravity only: no drag, fluids, fields, springs or
        Newtonian gravity), else None. Pinned and inactive bodies are not masked here; the
        array is the system's own (do not modify)."""
        return self._gravity_acc if self._plain and not self._air_drag else None

    def moving(self) -> np.ndarray:
        """active and not pinned (cached until `active` is set again; do not modify)."""
        if self._moving is None:
            self._moving = self._active & self._free
        return self._moving

    def derivative(self, t: float, X: np.ndarray, dt: float) -> np.ndarray:
        """D(t, X) for a step of `dt` s: the whole system's rate of change, one vectorised pass.

        Small systems are dominated by the cost of each numpy call, not by arithmetic, so
        two exact shortcuts skip calls: every body moving (no masking) and no body spinning
        (w = 0 and no torques: dq/dt = 1/2 (0, 0) q = 0 and dw/dt = I^-1 (0 - 0 x I 0) = 0)."""
        s = self.unpack(X)
        move = self.moving()
        everyone = bool(move.all())
        acc = self.acceleration(t, s.x, s.v, dt)
        torque = self._contact(t, s, dt, move, acc)
        out = np.zeros(X.shape)
        n = self.n
        if not self.rotating:
            parts = ((slice(0, 3 * n), s.v), (slice(3 * n, 6 * n), acc))
        elif not s.w.any() and torque is None:
            parts = ((slice(0, 3 * n), s.v), (slice(7 * n, 10 * n), acc))
        else:
            dq = quat_rate(s.q, s.w)
            alpha = angular_acceleration(s.q, s.w, self.props.inertia, self.props.inv_inertia, np.zeros_like(s.w) if torque is None else torque)
            parts = ((slice(0, 3 * n), s.v), (slice(3 * n, 7 * n), dq), (slice(7 * n, 10 * n), acc), (slice(10 * n, 13 * n), alpha))
        for where, rate in parts:
            out[where] = (rate if everyone else np.where(move[:, None], rate, 0.0)).ravel()
        return out

    def velocity_rate(self, t: float, X: np.ndarray, dt: float) -> np.ndarray:
        """The velocity-like part of D (accelerations, angular accelerations): D[split:]
        without the position-like rates (semi-implicit Euler uses only this part); a new
        array, which the integrator may scale in place."""
        s = self.unpack(X)
        move = self.moving()
        acc = self.acceleration(t, s.x, s.v, dt)
        torque = self._contact(t, s, dt, move, acc)
        everyone = bool(move.all())
        if not everyone:
            acc = np.where(move[:, None], acc, 0.0)
        if not self.rotating:
            return acc.ravel()
        n = self.n
        out = np.zeros(6 * n)
        out[: 3 * n] = acc.ravel()
        if s.w.any() or torque is not None:
            alpha = angular_acceleration(s.q, s.w, self.props.inertia, self.props.inv_inertia, np.zeros_like(s.w) if torque is None else torque)
            out[3 * n :] = (alpha if everyone else np.where(move[:, None], alpha, 0.0)).ravel()
        return out

    def _contact(self, t: float, s: State, dt: float, move: np.ndarray, acc: np.ndarray) -> np.ndarray | None:
        """Penalty contacts' share of D: adds their force / m to `acc` in place and returns
        their torques [n, 3] (None: no penalty contact touches)."""
        if self.penalty is None:
            return None
        out = self.penalty.forces(s.x, s.q, s.v, s.w, dt, move, t)
        if out is None:
            return None
        force, torque = out
        acc += force * self.props.inv_mass[:, None]
        return torque if self.rotating else None

    def position_rate(self, t: float, X: np.ndarray) -> np.ndarray:
        """The position-like part of D (velocities and quaternion rates): no forces needed."""
        s = self.unpack(X)
        move = self.moving()[:, None]
        if not self.rotating:
            return s.v.ravel() if move.all() else np.where(move, s.v, 0.0).ravel()
        if not s.w.any():  # no spin: dq/dt = 0 exactly
            out = np.zeros(self.split)
            out[: 3 * self.n] = np.where(move, s.v, 0.0).ravel()
            return out
        return np.concatenate((np.where(move, s.v, 0.0).ravel(), np.where(move, quat_rate(s.q, s.w), 0.0).ravel()))

    # --- energy ---------------------------------------------------------------------------

    def energy(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(kinetic [n], potential [n], shared potential) in J for moving bodies: kinetic
        1/2 m v^2 + 1/2 w.I w; potential of gravity and buoyancy per body; springs, Newtonian
        gravity and the penalty contacts' springs are shared between bodies."""
        s = self.unpack(X)
        p, env = self.props, self.env
        move = self.moving()
        kinetic = 0.5 * p.mass * np.einsum("ij,ij->i", s.v, s.v)
        if self.rotating and s.w.any() and self._isotropic:  # |R^T w| = |w|
            kinetic = kinetic + 0.5 * p.inertia[:, 0] * np.einsum("ij,ij->i", s.w, s.w)
        elif self.rotating and s.w.any():  # (no spin: no rotational energy)
            from ..motion.pose import quat_to_matrix

            w_body = np.einsum("nji,nj->ni", quat_to_matrix(s.q), s.w)
            kinetic = kinetic + 0.5 * np.einsum("ij,ij->i", p.inertia * w_body, w_body)
        potential = forces.gravity_energy(p.mass, env.gravity, s.x, self.x_ref)
        for fluid in env.fluids:
            potential = potential + forces.buoyancy_energy(s.x, p.radius_eq, fluid, env.gravity)
        shared = 0.0
        if env.springs is not None and env.springs.count:
            shared += float(forces.spring_energy(s.x, env.springs).sum())
        if env.newtonian is not None and self.n > 1:
            shared += forces.newtonian_energy(s.x[move], p.mass[move], *env.newtonian)
        if self.penalty is not None:
            shared += self.penalty.energy(s.x, s.q, move)
        if move.all():  # (the usual case: no masking passes)
            return kinetic, potential, shared
        return np.where(move, kinetic, 0.0), np.where(move, potential, 0.0), shared
