"""Integrators: the cannonball against its closed form, orders of convergence on the
harmonic oscillator, symplectic Euler's bounded energy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _dynamics_scenes import ball, floor, run
from motion.pipeline.dynamics.integrators import INTEGRATORS, make_integrator

V0 = 520.0
G = 9.81
R = 0.0694
VEL = [V0 * math.cos(math.radians(45)), V0 * math.sin(math.radians(45)), 0.0]
FLIGHT = 2 * V0 * math.sin(math.radians(45)) / G  # 74.96 s
RANGE = V0**2 / G  # 27.56 km
STEP = 0.05


def closed_form(t: np.ndarray) -> np.ndarray:
    return np.array([0.0, R, 0.0]) + np.outer(t, VEL) + 0.5 * np.outer(t * t, [0.0, -G, 0.0])


@pytest.fixture(scope="module")
def cannon(tmp_path_factory):
    """The cannonball (no drag) over a sea plane, once per integrator."""
    out = {}
    tmp = tmp_path_factory.mktemp("cannon")
    for name in INTEGRATORS:
        objects = [ball("ball", R, radius=R, mass=11.0, velocity=VEL, restitution=0.0), floor("sea", size=80000, restitution=0.0, friction=0.8)]
        out[name] = run(tmp, objects, 76.0, {"integrator": name, "step": STEP}, name=f"cannon_{name.replace('-', '_')}")
    return out


@pytest.mark.parametrize("name", ["midpoint", "heun", "rk4", "rk45"])
def test_cannonball_exact_for_second_order_and_up(cannon, name):
    # constant acceleration: every method of order >= 2 integrates the parabola exactly,
    # and cubic Hermite sampling between steps is exact for it too (sub-frame times)
    t = np.sort(np.random.default_rng(1).uniform(0.0, 74.0, 50))
    got = cannon[name].sample(t)["ball"].translation
    np.testing.assert_allclose(got, closed_form(t), rtol=1e-10, atol=1e-6)


@pytest.mark.parametrize("name, sign", [("euler", -1.0), ("semi-implicit-euler", 1.0)])
def test_cannonball_first_order_error_is_the_documented_one(cannon, name, sign):
    # explicit Euler: x_n = x0 + v0 t + a t^2/2 - a h t/2 ; semi-implicit: + a h t/2
    t = np.arange(1, 1400) * STEP
    got = cannon[name].sample(t)["ball"].translation
    expect = closed_form(t) + sign * 0.5 * STEP * np.outer(t, [0.0, -G, 0.0])
    np.testing.assert_allclose(got, expect, rtol=1e-9, atol=1e-6)
    err = np.abs(got[:, 1] - closed_form(t)[:, 1])
    assert err[-1] > 0.2 * t[-1] * 0.5  # a real first-order error, not zero


@pytest.mark.parametrize("name", ["rk4", "midpoint"])
@pytest.mark.parametrize("fraction", [0.0, 0.37, 0.999])
def test_release_between_steps_follows_the_closed_form_from_its_start(tmp_path, name, fraction):
    # a ball fired at `start`, which falls inside a step of the fixed grid: it joins at the
    # step's end on its own parabola from `start`, not one step late (0.63 step of 200 m/s
    # would be 1.3 m behind); a start exactly on the grid is the plain case
    step = 0.01
    start = 0.5 + fraction * step
    vel = [150.0, 130.0, 0.0]
    objects = [ball("b", 5.0, radius=0.1, velocity=vel, start=start), floor(size=1e5)]
    sim = run(tmp_path, objects, 1.5, {"integrator": name, "step": step}, name=f"release_{name.replace('-', '_')}")
    # held still until the step before the release, at every sub-step time too (no swing
    # from the launch velocity it holds), then on its parabola from the step after
    t = np.concatenate((np.linspace(0.0, 0.5, 37), np.linspace(0.52, 1.5, 41)))
    got = sim.sample(t)["b"].translation
    tau = np.maximum(t - start, 0.0)[:, None]
    expect = np.array([0.0, 5.0, 0.0]) + tau * vel + 0.5 * tau * tau * np.array([0.0, -G, 0.0])
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_cannonball_hits_the_sea_at_range_and_flight_time(cannon, name):
    impacts = cannon[name].bodies.impacts
    assert len(impacts), "the ball never hit the sea"
    t_hit = impacts[0, 0]
    x_hit = impacts[0, 4:7]
    exact = name not in ("euler", "semi-implicit-euler")
    tol_t = 1e-3 if exact else 2 * STEP
    assert abs(t_hit - FLIGHT) < tol_t
    assert abs(x_hit[0] - RANGE) < (0.5 if exact else V0 * 2 * STEP)
    assert x_hit[1] >= R - 1e-6  # on the sea, never through it
    assert abs(impacts[0, 2] - V0 * math.sin(math.radians(45))) < 1.0  # approach speed


# --- harmonic oscillator through the engine: a bob circling a pinned anchor ------------


OMEGA = 2 * math.pi


def oscillator_error(tmp_path, integrator: str, step: float, t_end: float = 0.7) -> float:
    objects = [
        ball("anchor", 0.0, radius=0.01, pinned=True, body="particle"),
        ball("bob", 0.0, radius=0.01, x=1.0, mass=1.0, body="particle", velocity=[0, 0, OMEGA]),
    ]
    dyn = {"integrator": integrator, "step": step, "gravity": [0, 0, 0], "springs": [{"a": "anchor", "b": "bob", "stiffness": OMEGA**2, "rest_length": 0.0}]}
    sim = run(tmp_path, objects, t_end, dyn, name=f"osc_{integrator.replace('-', '_')}_{int(1 / step)}")
    track = sim.bodies
    i = 1  # bob
    exact_x = np.array([math.cos(OMEGA * t_end), 0.0, math.sin(OMEGA * t_end)])
    exact_v = OMEGA * np.array([-math.sin(OMEGA * t_end), 0.0, math.cos(OMEGA * t_end)])
    assert track.times[-1] == pytest.approx(t_end)
    return float(max(np.abs(track.x[-1, i] - exact_x).max(), np.abs(track.v[-1, i] - exact_v).max() / OMEGA))


@pytest.mark.parametrize("name, order, step", [("euler", 1, 1 / 400), ("semi-implicit-euler", 1, 1 / 400), ("midpoint", 2, 1 / 100), ("heun", 2, 1 / 100), ("rk4", 4, 1 / 25)])
def test_order_of_convergence(tmp_path, name, order, step):
    e1 = oscillator_error(tmp_path, name, step)
    e2 = oscillator_error(tmp_path, name, step / 2)
    measured = math.log2(e1 / e2)
    assert abs(measured - order) < 0.25, f"{name}: measured order {measured:.3f}"


def test_rk45_meets_its_tolerance(tmp_path):
    objects = [
        ball("anchor", 0.0, radius=0.01, pinned=True, body="particle"),
        ball("bob", 0.0, radius=0.01, x=1.0, body="particle", velocity=[0, 0, OMEGA]),
    ]
    dyn = {"integrator": "rk45", "step": 0.1, "rtol": 1e-8, "atol": 1e-10, "gravity": [0, 0, 0], "springs": [{"a": "anchor", "b": "bob", "stiffness": OMEGA**2, "rest_length": 0.0}]}
    sim = run(tmp_path, objects, 1.0, dyn, name="rk45_tol")
    assert np.abs(sim.bodies.x[-1, 1] - [1.0, 0.0, 0.0]).max() < 1e-6
    assert len(sim.bodies.times) < 200  # it took big steps, not the tiniest


class Harmonic:
    """x'' = -x (omega = 1), X = (x, v): the smallest system the integrators accept."""

    split = 1

    def derivative(self, t, X):
        return np.array([X[1], -X[0]])

    def position_rate(self, t, X):
        return X[1:2]

    def normalize(self, X):
        return X


def test_symplectic_euler_energy_bounded_explicit_euler_grows():
    system = Harmonic()
    h = 2 * math.pi / 20
    periods = 10_000
    sym = make_integrator("semi-implicit-euler")
    X = np.array([1.0, 0.0])
    e_min, e_max = 1.0, 1.0
    for _ in range(periods):
        for _ in range(20):
            X = sym.step(system, 0.0, X, h).X
        e = X[0] ** 2 + X[1] ** 2
        e_min, e_max = min(e_min, e), max(e_max, e)
    # symplectic Euler conserves a modified energy: E stays within 1 +- h (omega h = 0.31)
    assert e_max < 1.0 + h and e_min > 1.0 - h
    exp = make_integrator("euler")
    X = np.array([1.0, 0.0])
    energies = []
    for _ in range(100):
        for _ in range(20):
            X = exp.step(system, 0.0, X, h).X
        energies.append(X[0] ** 2 + X[1] ** 2)
    assert np.all(np.diff(energies) > 0)
    # |amplification|^2 = 1 + (omega h)^2 per step
    assert energies[-1] == pytest.approx((1 + h * h) ** 2000, rel=1e-6)


def test_cannonball_scene_through_evaluate():
    # the shipped scene, simulated, seen by the motion stage at sub-frame times
    from pathlib import Path

    from motion.pipeline.dynamics import simulate
    from motion.pipeline.motion import evaluate
    from motion.pipeline.scene import load_scene

    loaded = load_scene(Path(__file__).parents[2] / "scenes" / "cannonball.yaml", overrides={"timeline": {"last": 240}})
    sim = simulate(loaded, 10.5)
    t = np.array([0.0, 1.0 / 96, 3.3333, 7.77, 10.0])
    got = evaluate(loaded, t, simulation=sim).objects["ball"].translation
    expect = np.array([0.0, 3.0, 0.0]) + np.outer(t, [367.69553, 367.69553, 0.0]) + 0.5 * np.outer(t * t, [0.0, -G, 0.0])
    np.testing.assert_allclose(got, expect, atol=1e-6)


class Falling:
    """x'' = a (constant), X = (x, v) in 3-D: what step.coast replaces by a closed form."""

    split = 3
    a = np.array([0.3, -9.81, 1.7])

    def derivative(self, t, X):
        return np.concatenate((X[3:], self.a))

    def position_rate(self, t, X):
        return X[3:].copy()

    def normalize(self, X):
        return X


@pytest.mark.parametrize("name", ["euler", "semi-implicit-euler", "midpoint", "heun", "rk4"])
def test_ballistic_closed_form_is_the_integrators_own_result(name):
    # the coast stage's x_k = x0 + k h v0 + c(k) h^2 a, v_k = v0 + k h a must be what k
    # steps of the integrator give (rounding aside), for every fixed-step integrator
    integ = make_integrator(name)
    system, h = Falling(), 1 / 96
    X = np.array([0.0, 3.0, -1.0, 367.7, 367.7, 2.0])
    x0, v0 = X[:3].copy(), X[3:].copy()
    for k in range(1, 401):
        X = integ.step(system, 0.0, X, h).X
        closed_x = x0 + k * h * v0 + integ.ballistic(float(k)) * h * h * system.a
        np.testing.assert_allclose(X[:3], closed_x, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(X[3:], v0 + k * h * system.a, rtol=1e-12, atol=1e-12)
