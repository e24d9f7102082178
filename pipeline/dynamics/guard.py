"""Stability guard: every step, the state must be finite and the energy bounded.

Bound: with E = kinetic + potential (gravity, buoyancy, springs, Newtonian gravity),
E_in = the energy at the start plus that of bodies spawned since (particles), and W_ext
the positive work done by wind and force fields (sum over steps of h * max(0, P)),
a run is a blow-up when

    E(t) > E_in + W_ext + (limit - 1) * max(|E_in|, E_floor)

with `limit` the scene's `dynamics.energy_growth_limit` (default 10) and
E_floor = sum m |g| r + 1e-9 J (so a system at rest may still move). Drag, friction and
inelastic contacts only remove energy, so any honest run stays under the bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SimulationError

_ADVICE = {
    "euler": "semi-implicit-euler or rk4",
    "semi-implicit-euler": "rk4",
    "midpoint": "rk4",
    "heun": "rk4",
    "rk4": "rk45 (adaptive)",
    "rk45": "a tighter rtol/atol",
}


@dataclass
class Guard:
    """Checks one group's state after each step; raises SimulationError on a blow-up."""

    names: list[str]
    integrator: str
    limit: float
    e_in: float
    e_floor: float
    w_ext: float = 0.0

    def add_energy(self, joules: float) -> None:
        """Energy brought in by newly spawned bodies."""
        self.e_in += joules

    def add_work(self, joules: float) -> None:
        """Work done on the group by wind and force fields over a step (only gains count)."""
        self.w_ext += max(0.0, joules)

    def bound(self) -> float:
        """The energy (J) past which the run is a blow-up (module docstring)."""
        return self.e_in + self.w_ext + (self.limit - 1.0) * max(abs(self.e_in), self.e_floor)

    def check(self, t: float, step: int, h: float, X: np.ndarray, per_body: np.ndarray, total: float, positions: np.ndarray) -> None:
        """per_body: each body's energy (to name the culprit); positions [n, 3]."""
        if not (np.isfinite(X).all() and math.isfinite(total)):  # (positions are part of X)
            bad = ~np.isfinite(positions).all(axis=1)
            culprit = self._name(int(np.argmax(bad)) if bad.any() else int(np.argmax(~np.isfinite(per_body)) if (~np.isfinite(per_body)).any() else 0))
            raise SimulationError(self._message(culprit, t, step, h, "its state became non-finite (NaN or inf)"))
        bound = self.bound()
        if total > bound:
            culprit = self._name(int(np.argmax(per_body)) if per_body.size else 0)
            raise SimulationError(
                self._message(culprit, t, step, h, f"the energy grew to {total:.4g} J, past the bound {bound:.4g} J (energy_growth_limit {self.limit:g} x the initial {self.e_in:.4g} J)")
            )

    def _name(self, i: int) -> str:
        return self.names[i] if 0 <= i < len(self.names) else f"body {i}"

    def _message(self, name: str, t: float, step: int, h: float, what: str) -> str:
        return (
            f"simulation blew up: object '{name}' at t = {t:.6g} s (step {step}, dt = {h:.4g} s, integrator {self.integrator}): {what}; "
            f"try a smaller dynamics.step (e.g. {h / 4:.3g}) or another integrator ({_ADVICE.get(self.integrator, 'rk4')})"
        )
