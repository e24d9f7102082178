"""Time integrators: advance X' = D(t, X) by one step.

Each integrator takes a `system` with `derivative(t, X)`, `position_rate(t, X)`, `split`
and `normalize(X)` (see state.System) and returns a `StepResult`: the new state, the step
actually taken and the step it proposes next (fixed-step methods: the same h).

| name                | method                         | order | D evaluations |
|---------------------|--------------------------------|-------|---------------|
| euler               | explicit Euler                 | 1     | 1             |
| semi-implicit-euler | symplectic Euler (v, then x)   | 1     | 1 (+ rates)   |
| midpoint            | explicit RK2 midpoint          | 2     | 2             |
| heun                | Heun (explicit trapezoid)      | 2     | 2             |
| rk4                 | classic Runge-Kutta            | 4     | 4             |
| rk45                | Dormand-Prince 5(4), adaptive  | 5     | 6 (FSAL: 7-1) |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..errors import SimulationError, UnknownIntegratorError


class StepSystem(Protocol):
    """What an integrator advances: D(t, X) for the step at hand (step.StepDynamics), the
    position-like part of D, the index `split` between position- and velocity-like
    entries of X, and the projection back onto the state manifold."""

    split: int

    def derivative(self, t: float, X: np.ndarray) -> np.ndarray:
        """D(t, X), a new array (integrators may scale it in place)."""
        ...

    def position_rate(self, t: float, X: np.ndarray) -> np.ndarray:
        """The position-like part of D(t, X)."""
        ...

    def normalize(self, X: np.ndarray) -> np.ndarray:
        """X projected back onto the state manifold (unit quaternions)."""
        ...


@dataclass(frozen=True)
class StepResult:
    """One step's outcome: the new state, the step taken (s) and the step proposed next (s)."""

    X: np.ndarray
    h_taken: float
    h_next: float


class Integrator:
    """A time integrator: `step` advances X' = D(t, X) by (at most) h; `adaptive` ones may
    take less and propose the next step."""

    name = ""
    order = 0
    adaptive = False
    # Under a constant acceleration a (D's velocity part independent of the state), k
    # steps of h from (x0, v0) give v_k = v0 + k h a and x_k = x0 + k h v0 + c(k) h^2 a;
    # `ballistic(k)` is that c(k) (None: no closed form used). step.coast relies on it.
    ballistic: "Callable[[np.ndarray], np.ndarray] | None" = None

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """Advance X at time t by one step of h."""
        raise NotImplementedError


class ExplicitEuler(Integrator):
    """X_{n+1} = X_n + h D(t_n, X_n). Error O(h) globally; energy grows on oscillators."""

    name, order = "euler", 1
    ballistic = staticmethod(lambda k: k * (k - 1) / 2.0)  # x moves with the old v

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """One explicit Euler step."""
        return StepResult(system.normalize(X + h * system.derivative(t, X)), h, h)


class SemiImplicitEuler(Integrator):
    """v_{n+1} = v_n + h a(t_n, x_n, v_n); x_{n+1} = x_n + h v_{n+1}. First order but
    symplectic: energy of a conservative system stays bounded (no drift)."""

    name, order = "semi-implicit-euler", 1
    ballistic = staticmethod(lambda k: k * (k + 1) / 2.0)  # x moves with the new v

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """Velocities first, then positions with the new velocities."""
        k = system.split
        out = X.copy()
        velocity_rate = getattr(system, "velocity_rate", None)  # only D[k:] is needed
        dv = velocity_rate(t, X) if velocity_rate is not None else system.derivative(t, X)[k:]
        dv *= h  # (a new array: scaled in place, one pass fewer over a big system)
        out[k:] += dv
        out[:k] += h * system.position_rate(t + h, out)
        return StepResult(system.normalize(out), h, h)


class Midpoint(Integrator):
    """RK2 midpoint: X_{n+1} = X_n + h D(t + h/2, X_n + h/2 D(t, X_n))."""

    name, order = "midpoint", 2
    ballistic = staticmethod(lambda k: k * k / 2.0)  # exact for a constant acceleration

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """One midpoint step."""
        k1 = system.derivative(t, X)
        k2 = system.derivative(t + 0.5 * h, X + 0.5 * h * k1)
        return StepResult(system.normalize(X + h * k2), h, h)


class Heun(Integrator):
    """Heun: predictor X* = X + h k1, X_{n+1} = X + h/2 (k1 + D(t + h, X*))."""

    name, order = "heun", 2
    ballistic = staticmethod(lambda k: k * k / 2.0)

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """One Heun step."""
        k1 = system.derivative(t, X)
        k2 = system.derivative(t + h, X + h * k1)
        return StepResult(system.normalize(X + 0.5 * h * (k1 + k2)), h, h)


class RK4(Integrator):
    """Classic Runge-Kutta: weights 1/6, 1/3, 1/3, 1/6 on the four stage slopes."""

    name, order = "rk4", 4
    ballistic = staticmethod(lambda k: k * k / 2.0)

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """One classic RK4 step."""
        k1 = system.derivative(t, X)
        k2 = system.derivative(t + 0.5 * h, X + 0.5 * h * k1)
        k3 = system.derivative(t + 0.5 * h, X + 0.5 * h * k2)
        k4 = system.derivative(t + h, X + h * k3)
        return StepResult(system.normalize(X + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)), h, h)


# Dormand-Prince 5(4) tableau (Dormand & Prince 1980; Hairer, Norsett, Wanner table 5.2).
_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
_A = [
    [],
    [1 / 5],
    [3 / 40, 9 / 40],
    [44 / 45, -56 / 15, 32 / 9],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
    [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
]
_B5 = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
_B4 = np.array([5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40])


class DormandPrince45(Integrator):
    """Adaptive embedded RK 5(4): the step is accepted when the error estimate
    ||y5 - y4|| / (atol + rtol |y|) (RMS norm) <= 1; the next step is
    h * clamp(0.9 err^(-1/5), 0.2, 5); the driver caps it at the scene's step so
    collisions are swept at least that often, and bounds the number of steps of a run
    (`dynamics.rk45_max_steps`). A step that would have to go below h_min raises a
    SimulationError instead of accepting an error past the tolerance."""

    name, order, adaptive = "rk45", 5, True

    def __init__(self, rtol: float = 1e-6, atol: float = 1e-9, h_min: float = 1e-12) -> None:
        self.rtol, self.atol, self.h_min = rtol, atol, h_min

    def step(self, system: StepSystem, t: float, X: np.ndarray, h: float) -> StepResult:
        """Try h, shrinking it until the error estimate is within tolerance."""
        k1 = system.derivative(t, X)
        while True:
            ks = [k1]
            for i in range(1, 7):
                xi = X + h * sum(a * k for a, k in zip(_A[i], ks) if a != 0.0)
                ks.append(system.derivative(t + _C[i] * h, xi))
            y5 = X + h * sum(b * k for b, k in zip(_B5, ks) if b != 0.0)
            y4 = X + h * sum(b * k for b, k in zip(_B4, ks) if b != 0.0)
            scale = self.atol + self.rtol * np.maximum(np.abs(X), np.abs(y5))
            err = float(np.sqrt(np.mean(((y5 - y4) / scale) ** 2))) if X.size else 0.0
            if not np.isfinite(err):
                err = 1e10
            factor = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
            if err <= 1.0:
                return StepResult(system.normalize(y5), h, h * factor)
            if h <= self.h_min:
                raise SimulationError(f"rk45 cannot meet rtol {self.rtol:g} / atol {self.atol:g} at t = {t:.9g} s even with a step of {h:.3g} s "
                                      "(a force that changes faster than any step: a stiff penalty contact?); loosen rtol/atol or soften the contact")
            h = max(self.h_min, h * factor)


INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (ExplicitEuler, SemiImplicitEuler, Midpoint, Heun, RK4, DormandPrince45)
}


def make_integrator(name: str, rtol: float = 1e-6, atol: float = 1e-9) -> Integrator:
    """The integrator named in a scene's `dynamics.integrator`."""
    if name == "rk45":
        return DormandPrince45(rtol=rtol, atol=atol)
    try:
        return INTEGRATORS[name]()
    except KeyError:
        raise UnknownIntegratorError(f"unknown integrator {name!r}; expected one of: {', '.join(INTEGRATORS)}") from None
