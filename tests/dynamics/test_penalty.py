"""Penalty-force contacts (`contact: penalty`, pipeline/dynamics/penalty.py) against their
closed forms: the resting sink m g / k, the linear spring-damper's restitution
exp(-zeta pi / sqrt(1 - zeta^2)) and contact time pi / omega_d, the elastic frictionless
reflection about the normal, each integrator's order of convergence inside a contact; the
validation's stability bound, rk45's budget; boxes, capsules and meshes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from motion.pipeline.dynamics import simulate
from motion.pipeline.errors import SceneError, SimulationError
from motion.pipeline.motion.pose import quat_to_matrix
from motion.pipeline.scene import load_scene
from motion.pipeline.scene.checks import scene_warnings
from motion.pipeline.scene.dynamics_schema import Penalty, damping_ratio, penalty_parameters, stability_limit
from _dynamics_scenes import ball, floor, run, write_scene

FIXED = ["euler", "semi-implicit-euler", "midpoint", "heun", "rk4"]
ORDERS = {"euler": 1, "semi-implicit-euler": 1, "midpoint": 2, "heun": 2, "rk4": 4}
G = 9.81


def _pen(restitution: float = 0.5, contact_time: float = 0.01, **extra: object) -> dict:
    return {"contact": "penalty", "restitution": restitution, "penalty": {"contact_time": contact_time}, **extra}


def _params(mass: float, restitution: float, contact_time: float):
    return penalty_parameters(Penalty(contact_time=contact_time), mass, restitution)


def test_parameters_from_restitution_and_contact_time_are_the_linear_oscillators() -> None:
    p = _params(2.0, 0.5, 0.01)
    assert p.restitution == pytest.approx(0.5, rel=1e-12)
    assert p.contact_time == pytest.approx(0.01, rel=1e-12)
    assert p.k == pytest.approx(2.0 * p.omega0**2) and p.c == pytest.approx(2 * p.zeta * 2.0 * p.omega0)
    assert damping_ratio(1.0) == 0.0 and damping_ratio(0.0) == 1.0


@pytest.mark.parametrize("integrator", FIXED + ["rk45"])
def test_resting_sphere_sinks_by_m_g_over_k(tmp_path: Path, integrator: str) -> None:
    mass, r = 0.7, 0.1
    p = _params(mass, 0.3, 0.02)
    sim = run(tmp_path, [floor(), ball("b", r, radius=r, mass=mass, **_pen(0.3, 0.02))], 0.6, {"integrator": integrator, "step": 0.001})
    y = sim.bodies.x[:, 0, 1]
    # the fixed point of every consistent integrator is the force balance k delta = m g
    assert y[-1] == pytest.approx(r - mass * G / p.k, abs=1e-9)
    assert abs(sim.bodies.v[-1, 0, 1]) < 1e-7


def _in_contact(tmp_path: Path, integrator: str, h: float, t_end: float, delta0: float, v0: float, restitution: float = 0.5):
    """A ball already pressed delta0 into the floor, moving into it at v0, no gravity."""
    r = 0.1
    objects = [floor(restitution=1.0, friction=0.0), ball("b", r - delta0, radius=r, mass=1.0, velocity=[0, -v0, 0], friction=0.0, **_pen(restitution))]
    return run(tmp_path, objects, t_end, {"integrator": integrator, "step": h, "gravity": [0, 0, 0]}), r


def test_each_integrator_converges_at_its_order_inside_a_contact(tmp_path: Path) -> None:
    """Inside the contact the force is smooth (the depth stays > 0): the error of the
    depth half way through against the damped oscillator's closed form falls as h^order."""
    p = _params(1.0, 0.5, 0.01)
    delta0, v0, t_end = 1e-3, 1.0, 0.005
    wd = p.omega0 * math.sqrt(1 - p.zeta**2)
    exact = math.exp(-p.zeta * p.omega0 * t_end) * (delta0 * math.cos(wd * t_end) + (v0 + p.zeta * p.omega0 * delta0) / wd * math.sin(wd * t_end))
    measured = {}
    for integrator in FIXED:
        errors = []
        for n in (10, 20, 40):
            sim, r = _in_contact(tmp_path, integrator, t_end / n, t_end, delta0, v0)
            errors.append(abs((r - sim.bodies.x[-1, 0, 1]) - exact))
        measured[integrator] = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
        assert measured[integrator][-1] == pytest.approx(ORDERS[integrator], abs=0.25), (integrator, errors)


@pytest.mark.parametrize("integrator", FIXED + ["rk45"])
def test_restitution_and_contact_time_match_the_linear_spring_damper(tmp_path: Path, integrator: str) -> None:
    """After the contact the ball flies freely (no gravity): its speed is e v0, and where it
    is says when it left. The force jumps at separation (c d(delta)/dt is not 0 there), so
    every integrator converges to these at first order. At 400 steps a contact: explicit
    Euler 1.1e-2 relative (it gains energy), the others 2e-3 or better."""
    e, t_c, v0, delta0 = 0.5, 0.01, 1.0, 1e-9
    h, t_end = t_c / 400, 0.03
    sim, r = _in_contact(tmp_path, integrator, h, t_end, delta0, v0, e)
    v_out = sim.bodies.v[-1, 0, 1]
    t_sep = t_end - (sim.bodies.x[-1, 0, 1] - r) / v_out
    assert v_out / v0 == pytest.approx(e, rel=1.5e-2 if integrator == "euler" else 2e-3)
    assert t_sep == pytest.approx(t_c, rel=2e-3)


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "heun"])
def test_restitution_error_is_first_order_in_the_step(tmp_path: Path, integrator: str) -> None:
    e, v0 = 0.5, 1.0
    errs = []
    for n in (100, 200, 400):
        sim, _ = _in_contact(tmp_path, integrator, 0.01 / n, 0.02, 1e-9, v0, e)
        errs.append(abs(sim.bodies.v[-1, 0, 1] / v0 - e))
    orders = [math.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert errs[-1] < 2e-3 and min(orders) == pytest.approx(1.0, abs=0.1), (errs, orders)


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4", "rk45"])
def test_elastic_frictionless_contact_reflects_the_velocity_about_the_normal(tmp_path: Path, integrator: str) -> None:
    tilt = math.radians(20.0)
    n = np.array([0.0, math.cos(tilt), math.sin(tilt)])  # the tilted floor's normal
    ramp = floor(restitution=1.0, friction=0.0)
    ramp["transform"]["rotate"] = {"euler": [-90 + 20, 0, 0]}
    v_in = np.array([0.6, -1.0, -0.3])
    start = 0.1 * n + (0.1 + 0.02) * n - 0.02 * v_in  # a little way off the ramp, heading into it
    body = ball("b", 0.0, radius=0.1, mass=1.0, velocity=v_in.tolist(), friction=0.0, contact="penalty", penalty={"restitution": 1.0, "contact_time": 0.01})
    body["transform"]["translate"] = (start - 0.1 * n).tolist()
    sim = run(tmp_path, [ramp, body], 0.08, {"integrator": integrator, "step": 0.0001, "gravity": [0, 0, 0]})
    v_out = sim.bodies.v[-1, 0]
    np.testing.assert_allclose(v_out, v_in - 2 * (v_in @ n) * n, atol=2e-3)


def test_validation_refuses_a_step_past_the_stability_bound_with_its_numbers(tmp_path: Path) -> None:
    path = write_scene(tmp_path, [floor(), ball("b", 1.0, mass=1.0, **_pen(0.5, 0.01))], {"integrator": "euler", "step": 0.002})
    with pytest.raises(SceneError) as info:
        load_scene(path)
    text = str(info.value)
    p = _params(1.0, 0.5, 0.01)
    bound_ms = stability_limit("euler", p.zeta) / p.omega0 * 1e3
    assert "objects[1].motion" in text and "stability bound of euler" in text
    assert f"h < {bound_ms:.4g} ms" in text and f"sqrt(m/k) = {1e3 / p.omega0:.4g} ms" in text and "the step is 2 ms" in text
    # an undamped spring gains energy under explicit Euler at any step
    path = write_scene(tmp_path, [floor(), ball("b", 1.0, **_pen(1.0, 0.01))], {"integrator": "euler", "step": 1e-6}, name="elastic")
    with pytest.raises(SceneError, match="unstable on this contact at any step"):
        load_scene(path)
    # the same contact at a quarter of the bound, or under rk4, loads
    load_scene(write_scene(tmp_path, [floor(), ball("b", 1.0, **_pen(0.5, 0.01))], {"integrator": "euler", "step": bound_ms / 4e3}, name="ok"))


def test_an_under_resolved_contact_is_a_warning(tmp_path: Path) -> None:
    loaded = load_scene(write_scene(tmp_path, [floor(), ball("b", 1.0, **_pen(0.5, 0.01))], {"integrator": "rk4", "step": 0.0025}))
    warnings = [w for w in scene_warnings(loaded.scene) if "penalty" in w]
    assert len(warnings) == 1 and "lasts 4 steps" in warnings[0] and "dynamics.step <= 0.001" in warnings[0]


def test_rk45_steps_down_for_a_stiff_contact_within_its_budget_and_refuses_past_it(tmp_path: Path) -> None:
    objects = [floor(), ball("b", 0.3, radius=0.1, **_pen(0.5, 0.002))]
    sim = run(tmp_path, objects, 0.5, {"integrator": "rk45", "step": 0.01})
    steps = np.diff(sim.bodies.times)
    assert steps.min() < 0.002 / 10  # it stepped well below the contact time
    with pytest.raises(SimulationError, match="budget of 40 steps.*penalty contact"):
        run(tmp_path, objects, 0.5, {"integrator": "rk45", "step": 0.01, "rk45_max_steps": 40})


def _box(name: str, y: float, size: float = 0.2, rot: tuple[float, float, float] = (0, 0, 0), **motion: object) -> dict:
    return {"name": name, "shape": "cube", "size": size, "transform": {"translate": [0, y, 0], "rotate": {"euler": list(rot)}}, "motion": {"type": "dynamics", **motion}}


def _up(sim) -> np.ndarray:
    return quat_to_matrix(sim.bodies.q[-1])[:, :, 1]


def test_a_box_dropped_on_an_edge_rests_flat_on_four_corners(tmp_path: Path) -> None:
    p = _params(1.0, 0.3, 0.01)
    sim = run(tmp_path, [floor(), _box("b", 0.4, rot=(0, 0, 30), mass=1.0, **_pen(0.3))], 1.2, {"integrator": "rk4", "step": 0.001})
    assert _up(sim)[0] @ np.array([0, 1, 0]) > math.cos(math.radians(0.01))
    assert sim.bodies.x[-1, 0, 1] == pytest.approx(0.1 - G / (4 * p.k), abs=1e-8)
    assert np.abs(sim.bodies.v[-1]).max() < 1e-6


def test_a_capsule_rests_on_its_side_and_a_mesh_on_its_hull(tmp_path: Path) -> None:
    p = _params(1.0, 0.3, 0.01)
    capsule = {"name": "c", "shape": "capsule", "radius": 0.05, "height": 0.3, "transform": {"translate": [0, 0.2, 0], "rotate": {"euler": [0, 0, 85]}},
               "motion": {"type": "dynamics", "mass": 1.0, **_pen(0.3)}}
    (tmp_path / "cube.obj").write_text("".join(f"v {x} {y} {z}\n" for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1))
                                       + "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n")
    mesh = {"name": "m", "shape": "mesh", "file": "cube.obj", "transform": {"translate": [1.0, 0.3, 0]}, "motion": {"type": "dynamics", "mass": 1.0, **_pen(0.3)}}
    sim = run(tmp_path, [floor(), capsule, mesh], 1.2, {"integrator": "rk4", "step": 0.001})
    assert sim.bodies.x[-1, 0, 1] == pytest.approx(0.05 - G / (2 * p.k), abs=1e-8)  # two cap spheres
    assert abs(_up(sim)[0, 1]) < 1e-6  # lying flat on its side
    assert sim.bodies.x[-1, 1, 1] == pytest.approx(0.1 - G / (4 * p.k), abs=1e-8)  # four hull vertices


def test_bodies_press_on_each_other_with_equal_and_opposite_forces(tmp_path: Path) -> None:
    """Head on, elastic, equal masses: they swap velocities and keep their momentum; an
    aligned stack of two boxes stands (their corners lie on each other's edges)."""
    pen = {"contact": "penalty", "friction": 0.0, "penalty": {"restitution": 1.0, "contact_time": 0.01}}
    sim = run(tmp_path, [ball("a", 1, x=-0.3, velocity=[1, 0, 0], **pen), ball("b", 1, x=0.3, velocity=[-1, 0, 0], mass=1.0, **pen)], 0.5,
              {"integrator": "rk4", "step": 0.0002, "gravity": [0, 0, 0]})
    momentum = sim.bodies.v.sum(axis=1)
    assert np.abs(momentum).max() < 1e-12
    np.testing.assert_allclose(sim.bodies.v[-1, :, 0], [-1.0, 1.0], atol=1e-4)
    stack = run(tmp_path, [floor(), _box("a", 0.1, **_pen(0.3)), _box("b", 0.3, **_pen(0.3))], 1.0, {"integrator": "rk4", "step": 0.001}, name="stack")
    assert 0.29 < stack.bodies.x[-1, 1, 1] < 0.3 and np.abs(stack.bodies.x[-1, :, 0]).max() < 1e-6


def test_friction_stops_a_slide_at_the_coulomb_distance_and_a_ball_rolls_at_five_sevenths(tmp_path: Path) -> None:
    mu, v0 = 0.5, 2.0
    box = _box("b", 0.1, velocity=[v0, 0, 0], friction=mu, static_friction=mu, **_pen(0.3, 0.01))
    ground = floor(friction=mu, static_friction=mu)
    sim = run(tmp_path, [ground, box], 0.6, {"integrator": "semi-implicit-euler", "step": 0.0005})
    assert sim.bodies.x[-1, 0, 0] == pytest.approx(v0 * v0 / (2 * mu * G), rel=0.01)
    assert abs(sim.bodies.v[-1, 0, 0]) < 1e-6  # stopped, not reversed
    rolling = run(tmp_path, [ground, ball("b", 0.1, velocity=[v0, 0, 0], friction=mu, **_pen(0.3, 0.01))], 0.6,
                  {"integrator": "rk4", "step": 0.0005}, name="roll")
    assert rolling.bodies.v[-1, 0, 0] == pytest.approx(5 / 7 * v0, rel=0.01)


def test_the_simulation_wide_switch_and_a_body_that_keeps_impulses(tmp_path: Path) -> None:
    objects = [floor(), ball("p", 0.1, radius=0.1, mass=1.0), ball("i", 0.1, x=1.0, radius=0.1, mass=1.0, contact="impulse")]
    sim = run(tmp_path, objects, 0.5, {"integrator": "rk4", "step": 0.001, "contact": "penalty", "penalty": {"contact_time": 0.01}})
    p = _params(1.0, 0.5, 0.01)
    assert sim.bodies.x[-1, 0, 1] == pytest.approx(0.1 - G / p.k, abs=1e-8)  # sinks: penalty
    assert sim.bodies.x[-1, 1, 1] == pytest.approx(0.1, abs=1e-12)  # stays on the surface: impulses


def test_the_bouncing_balls_example_validates_bakes_and_renders_with_penalty_contacts(tmp_path: Path) -> None:
    from _support import SCENES, run_motion
    from motion.pipeline.frame_output import read_frame

    doc = yaml.safe_load((SCENES / "bouncing-balls.yaml").read_text())
    doc["dynamics"]["contact"] = "penalty"
    path = tmp_path / "bouncing-balls.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert run_motion("validate", str(path)).returncode == 0
    bake = run_motion("bake", str(path), "-o", str(tmp_path / "motion.json"))
    assert bake.returncode == 0, bake.stderr
    assert (tmp_path / "motion.json").stat().st_size > 0
    sim = simulate(load_scene(path), 4.0)
    lowest = sim.bodies.x[:, :, 1].min(axis=0)
    assert (lowest < 0.2).all() and (lowest > 0.18).all()  # they pressed into the floor, a few mm
    out = tmp_path / "out"
    proc = run_motion("render", str(path), "--preset", "ci-smoke", "--frames", "20-20", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(next(out.glob("*.exr")))
    assert frame.rgba.shape == (36, 64, 4) and np.isfinite(frame.rgba).all() and frame.rgba[..., :3].std() > 1e-3


def test_a_penalty_body_keeps_impulses_against_a_mesh_collider(tmp_path: Path) -> None:
    """A capsule collider is a mesh collider: the penalty ball resting on it is held on its
    surface by impulses (no sink), beside a cylinder resting on the floor on its 8 rim
    points (sinks m g / (8 k))."""
    p = _params(1.0, 0.3, 0.02)
    capsule = {"name": "cc", "shape": "capsule", "radius": 0.2, "height": 1.0, "transform": {"translate": [2, 0.2, 0], "rotate": {"euler": [0, 0, 90]}},
               "collider": {"restitution": 0.5}}
    cylinder = {"name": "c", "shape": "cylinder", "radius": 0.1, "height": 0.2, "transform": {"translate": [0, 0.12, 0]},
                "motion": {"type": "dynamics", "mass": 1.0, **_pen(0.3, 0.02)}}
    sim = run(tmp_path, [floor(), capsule, cylinder, ball("b", 0.55, x=2.0, radius=0.1, mass=1.0, **_pen(0.3, 0.02))], 0.6, {"integrator": "rk4", "step": 0.001})
    assert sim.bodies.x[-1, 0, 1] == pytest.approx(0.1 - G / (8 * p.k), abs=1e-8)
    assert sim.bodies.x[-1, 1, 1] == pytest.approx(0.5, abs=1e-9)
