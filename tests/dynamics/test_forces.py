"""Forces: drag (terminal velocity), buoyancy, springs, Newtonian gravity, wind and force
fields, rigid rotation, and the blow-up guard."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _dynamics_scenes import ball, run, write_scene
from motion.pipeline.dynamics import simulate
from motion.pipeline.dynamics.forces import sphere_cap_volume
from motion.pipeline.errors import SimulationError
from motion.pipeline.scene import load_scene


def test_terminal_velocity(tmp_path):
    m, r, cd, rho, g = 1.0, 0.1, 0.47, 1.225, 9.81
    v_t = math.sqrt(2 * m * g / (rho * cd * math.pi * r * r))  # 32.9 m/s
    sim = run(tmp_path, [ball("b", 2000.0, radius=r, mass=m, drag={"cd": cd})], 20.0, {"integrator": "rk4", "step": 0.02})
    v = sim.bodies.v[:, 0, 1]
    assert abs(-v[-1] - v_t) / v_t < 0.005
    assert np.all(np.diff(v) <= 1e-12)  # drag never turns the fall around


def test_drag_never_reverses_velocity_even_with_a_huge_step(tmp_path):
    # linear drag k/m = 1000/s with h = 0.1 s: explicit Euler would reverse v 99 times over
    sim = run(tmp_path, [ball("b", 0.0, velocity=[10, 0, 0], drag={"cd": 0.0, "linear": 1000.0})], 1.0, {"integrator": "euler", "step": 0.1, "gravity": [0, 0, 0]})
    vx = sim.bodies.v[:, 0, 0]
    assert np.all(vx >= 0) and vx[-1] == 0.0


@pytest.mark.parametrize("rho_body", [300.0, 700.0])
def test_buoyancy_floating_fraction(tmp_path, rho_body):
    r = 0.1
    mass = rho_body * 4 / 3 * math.pi * r**3
    dyn = {"integrator": "rk4", "step": 0.005, "fluids": [{"level": 0.0, "density": 1000.0, "drag_cd": 0.5}]}
    sim = run(tmp_path, [ball("buoy", 0.5, radius=r, mass=mass, drag={"cd": 0.0, "linear": 8.0})], 12.0, dyn, name=f"buoy{int(rho_body)}")
    y = sim.bodies.x[-1, 0, 1]
    fraction = sphere_cap_volume(np.array(0.0 - (y - r)), np.array(r)) / (4 / 3 * math.pi * r**3)
    assert abs(fraction - rho_body / 1000.0) < 0.01 * rho_body / 1000.0


def test_spring_chain_rests_at_hooke_extension(tmp_path):
    # a 2 kg bob on a k = 200 N/m spring (damped) from a pinned anchor: extension m g / k
    objects = [ball("top", 3.0, pinned=True, radius=0.05), ball("bob", 2.0, mass=2.0, radius=0.05, body="particle")]
    dyn = {"integrator": "semi-implicit-euler", "step": 0.002, "springs": [{"a": "top", "b": "bob", "stiffness": 200.0, "damping": 10.0, "rest_length": 1.0}]}
    sim = run(tmp_path, objects, 5.0, dyn)
    assert sim.bodies.x[-1, 1, 1] == pytest.approx(3.0 - 1.0 - 2.0 * 9.81 / 200.0, abs=1e-6)
    assert np.all(sim.bodies.x[:, 0] == sim.bodies.x[0, 0])


def test_newtonian_two_body_circular_orbit(tmp_path):
    # equal masses M at distance d orbit their centre with v = sqrt(G M / (2 d))
    G, M, d = 1.0, 1.0, 2.0
    v = math.sqrt(G * M / (2 * d))
    objects = [ball("a", 0.0, x=-1.0, mass=M, radius=0.01, body="particle", velocity=[0, 0, -v]), ball("b", 0.0, x=1.0, mass=M, radius=0.01, body="particle", velocity=[0, 0, v])]
    dyn = {"integrator": "rk4", "step": 0.01, "gravity": [0, 0, 0], "newtonian_gravity": {"G": G, "softening": 0.0}}
    period = 2 * math.pi * 1.0 / v
    sim = run(tmp_path, objects, period, dyn)
    dist = np.linalg.norm(sim.bodies.x[:, 0] - sim.bodies.x[:, 1], axis=1)
    np.testing.assert_allclose(dist, d, rtol=1e-6)
    np.testing.assert_allclose(sim.bodies.x[-1, 0], [-1, 0, 0], atol=1e-4)


def test_wind_and_force_field_expressions(tmp_path):
    # a light ball in a steady 5 m/s wind with strong linear drag drifts at the wind speed;
    # a force field of 2 t N/kg along z adds v_z = t^2
    b = ball("b", 0.0, mass=0.1, drag={"cd": 0.0, "linear": 10.0})
    dyn = {"integrator": "rk4", "step": 0.01, "gravity": [0, 0, 0], "wind": ["5", "0", "0"], "force_field": ["0", "0", "2 * t"]}
    sim = run(tmp_path, [b], 2.0, dyn)
    v = sim.bodies.v[-1, 0]
    assert v[0] == pytest.approx(5.0, rel=1e-4)
    # z: dv/dt = 2 t - 100 v_z  ->  v_z ~ (2 t - 0.02) / 100 after the transient
    assert v[2] == pytest.approx((2 * 2.0 - 0.02) / 100.0, rel=1e-3)


def test_rigid_body_spins_about_its_axis(tmp_path):
    cube = {"name": "c", "shape": "cube", "size": [1, 0.2, 0.5], "transform": {"translate": [0, 5, 0]},
            "motion": {"type": "dynamics", "angular_velocity": [0, 90, 0]}}
    sim = run(tmp_path, [cube], 1.0, {"integrator": "rk4", "step": 0.01, "gravity": [0, 0, 0]})
    q = sim.sample(np.array([0.5, 1.0]))["c"].rotation
    # rotation of 45 and 90 degrees about +Y: (cos(a/2), 0, sin(a/2), 0)
    np.testing.assert_allclose(q[0], [math.cos(math.pi / 8), 0, math.sin(math.pi / 8), 0], atol=1e-6)
    np.testing.assert_allclose(q[1], [math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0], atol=1e-6)


def test_blow_up_is_a_clear_error_not_nans(tmp_path):
    objects = [ball("anchor", 0.0, pinned=True, radius=0.01), ball("bob", 0.0, x=1.2, body="particle", radius=0.01)]
    dyn = {"integrator": "euler", "step": 0.01, "gravity": [0, 0, 0], "springs": [{"a": "anchor", "b": "bob", "stiffness": 1.0e6, "rest_length": 1.0}]}
    with pytest.raises(SimulationError) as info:
        simulate(load_scene(write_scene(tmp_path, objects, dyn)), 5.0)
    msg = str(info.value)
    assert "'bob'" in msg and "t = " in msg and "step " in msg and "dt = 0.01" in msg
    assert "smaller dynamics.step" in msg and "semi-implicit-euler or rk4" in msg
    assert "\n" not in msg
