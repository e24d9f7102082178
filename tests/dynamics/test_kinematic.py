"""Kinematic colliders: keyed, procedural and parented colliders push bodies with their own
velocity (closed forms), nothing tunnels through a fast one, and what the dynamics stage
refuses, validation refuses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from _dynamics_scenes import ball, run, write_scene
from motion.pipeline.errors import SceneError
from motion.pipeline.scene import load_scene


def platform(keys: list[dict[str, Any]], name: str = "lift", restitution: float = 1.0) -> dict[str, Any]:
    """A 4 x 0.2 x 4 m box collider whose centre is keyed (linear, seconds); its top is at
    the keyed y + 0.1."""
    return {"name": name, "shape": "cube", "size": 1.0, "transform": {"scale": [4, 0.2, 4]},
            "collider": {"restitution": restitution, "friction": 0.0},
            "motion": {"type": "keyframes", "time_unit": "seconds", "interpolation": "linear", "channels": {"translate": {"keys": keys}}}}


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_a_ball_resting_on_a_rising_platform_leaves_at_its_speed(tmp_path: Path, integrator: str) -> None:
    """The platform rises at v from 0.5 s to 1 s, then stops: the ball it carried moves at v
    when it stops (to rounding) and flies on ballistically from there."""
    v, step = 2.0, 1.0 / 480
    keys = [{"time": 0, "value": [0, -0.1, 0]}, {"time": 0.5, "value": [0, -0.1, 0]}, {"time": 1.0, "value": [0, -0.1 + 0.5 * v, 0]}]
    sim = run(tmp_path, [ball("b", 0.1, restitution=0.0, friction=0.0), platform(keys)], 1.3, {"integrator": integrator, "step": step})
    tr = sim.bodies
    k = int(np.argmin(np.abs(tr.times - 1.0)))
    assert abs(tr.times[k] - 1.0) < 1e-9
    assert abs(tr.v[k, 0, 1] - v) < 1e-6
    assert abs(tr.x[k, 0, 1] - (0.5 * v + 0.1)) < 1e-9  # on the platform's top all the way
    if integrator == "rk4":  # exact in free flight under gravity
        t = tr.times[-1] - 1.0
        assert abs(tr.x[-1, 0, 1] - (0.5 * v + 0.1 + v * t - 0.5 * 9.81 * t * t)) < 1e-9


@pytest.mark.parametrize("integrator", ["euler", "semi-implicit-euler", "midpoint", "rk4", "rk45"])
def test_a_ball_dropped_on_a_rising_platform_leaves_at_e_v_in_plus_u_plus_u(tmp_path: Path, integrator: str) -> None:
    """Closed form for an infinite-mass wall moving at u: the relative velocity reverses
    with restitution e, so the ball leaves at e (v_in + u) + u. No gravity, so the velocity
    after the bounce is exactly that (impulses: to rounding)."""
    u, v_in, e = 1.0, 3.0, 0.8
    keys = [{"time": 0, "value": [0, -0.1, 0]}, {"time": 2.0, "value": [0, -0.1 + 2 * u, 0]}]
    sim = run(tmp_path, [ball("b", 1.1, restitution=e, friction=0.0, velocity=[0, -v_in, 0]), platform(keys)], 0.8,
              {"integrator": integrator, "step": 1e-3, "gravity": [0, 0, 0]})
    assert abs(sim.bodies.v[-1, 0, 1] - (e * (v_in + u) + u)) < 1e-6
    assert abs(sim.bodies.v[-1, 0, [0, 2]]).max() < 1e-12


@pytest.mark.parametrize("integrator,step", [("rk4", 1e-4), ("semi-implicit-euler", 2e-5)])
def test_penalty_contact_with_a_rising_platform_within_one_percent(tmp_path: Path, integrator: str, step: float) -> None:
    """The same bounce with penalty contacts (the spring's rebound is e against the
    surface: the closed form holds for the relative motion) within 1 %."""
    u, v_in, e = 1.0, 3.0, 0.8
    keys = [{"time": 0, "value": [0, -0.1, 0]}, {"time": 2.0, "value": [0, -0.1 + 2 * u, 0]}]
    sim = run(tmp_path, [ball("b", 0.25, restitution=e, friction=0.0, velocity=[0, -v_in, 0]), platform(keys)], 0.15,
              {"integrator": integrator, "step": step, "gravity": [0, 0, 0], "contact": "penalty", "penalty": {"contact_time": 0.01}})
    expected = e * (v_in + u) + u
    assert abs(sim.bodies.v[-1, 0, 1] - expected) < 0.01 * expected
    gap = sim.bodies.x[:, 0, 1] - 0.1 - u * sim.bodies.times  # above the platform's top (0 + u t)
    assert gap.min() < -1e-3  # a spring contact: it pressed into the platform


def test_a_fast_paddle_does_not_tunnel_through_a_ball(tmp_path: Path) -> None:
    """A 0.05 m thick paddle swept at 200 m/s (0.4 m a step, 8 times its thickness) through
    a ball at rest: caught by the relative sweep, the ball leaves at (1 + e) u."""
    u, e = 200.0, 0.5
    keys = [{"time": 0, "value": [-3, 0, 0]}, {"time": 1, "value": [-3 + u, 0, 0]}]
    paddle = {"name": "paddle", "shape": "cube", "size": 1.0, "transform": {"scale": [0.05, 2, 2]},
              "collider": {"restitution": e, "friction": 0.0},
              "motion": {"type": "keyframes", "time_unit": "seconds", "interpolation": "linear", "channels": {"translate": {"keys": keys}}}}
    sim = run(tmp_path, [ball("b", 0.0, restitution=1.0, friction=0.0), paddle], 0.03, {"integrator": "rk4", "step": 0.002, "gravity": [0, 0, 0]})
    assert abs(sim.bodies.v[-1, 0, 0] - (1 + e) * u) < 1e-6


def test_a_spinning_parented_bat_pushes_with_its_point_velocity(tmp_path: Path) -> None:
    """A bat (a 1 x 0.2 x 0.1 m box collider) hangs at x = R from a hub spinning about +Y
    at w (a procedural turntable, the bat a child): its face meets a resting ball
    (centre (R, 0, -0.3), radius 0.05) at the angle theta with R sin theta - 0.3 cos theta =
    -0.1. The face's normal velocity there is w d, d = R cos theta + 0.3 sin theta (the
    centre's distance along the bat), so the elastic ball leaves at 2 w d along the face's
    normal -(sin theta, 0, cos theta)."""
    w_deg, R = 90.0, 2.0
    w = np.radians(w_deg)
    hub = {"name": "hub", "shape": "cube", "size": 0.01, "motion": {"type": "procedural", "generators": [{"type": "turntable", "axis": [0, 1, 0], "rate": w_deg}]}}
    bat = {"name": "bat", "shape": "cube", "size": 1.0, "parent": "hub", "transform": {"translate": [R, 0, 0], "scale": [1.0, 0.2, 0.1]},
           "collider": {"restitution": 1.0, "friction": 0.0}}
    sim = run(tmp_path, [ball("b", 0.0, x=R, z=-0.3, radius=0.05, restitution=1.0, friction=0.0), hub, bat], 0.2,
              {"integrator": "rk4", "step": 1e-4, "gravity": [0, 0, 0]})
    from scipy.optimize import brentq

    theta = brentq(lambda a: R * np.sin(a) - 0.3 * np.cos(a) + 0.1, 0.0, 0.5)
    d = R * np.cos(theta) + 0.3 * np.sin(theta)
    expected = -2 * w * d * np.array([np.sin(theta), 0.0, np.cos(theta)])
    assert np.abs(sim.bodies.v[-1, 0] - expected).max() < 1e-3 * 2 * w * d


def _dust(speed: float, x: float = 3.0) -> dict[str, Any]:
    """An emitter at (x, 0, 0) firing 20 particles a second along -X at `speed`, elastic."""
    return {"name": "dust", "shape": "particles", "radius": 0.01, "transform": {"translate": [x, 0, 0]},
            "emitter": {"rate": 20, "lifetime": 2.0, "direction": [-1, 0, 0], "speed": speed, "spread": 0, "restitution": 1.0, "friction": 0.0}}


def _bounced(birth: np.ndarray, t: float, speed: float, u: float, face0: float, x_emit: float = 3.0, r: float = 0.01) -> np.ndarray:
    """Closed form: a particle born at `birth` at x_emit moving at -speed meets a face at
    face0 + u t when x_emit - speed (t_c - birth) - r = face0 + u t_c, and leaves at
    speed + 2u (elastic off a wall moving at u)."""
    t_c = (x_emit - r - face0 + speed * birth) / (speed + u)
    x_c = x_emit - speed * (t_c - birth)
    return np.where(t > t_c, x_c + (speed + 2 * u) * (t - t_c), x_emit - speed * (t - birth))


def test_particles_bounce_off_a_moving_body_at_its_pose(tmp_path: Path) -> None:
    """A 0.5 m crate (a dynamics body) slides at u = 2 m/s towards an emitter firing along
    -X at 5 m/s: each particle bounces off the crate's face where the face is at that
    moment (x = 0.25 + u t), leaving at 5 + 2u = 9 m/s; the crate does not feel them (it
    keeps u exactly). Positions to the float32 records (1e-6 m)."""
    u, speed = 2.0, 5.0
    crate = {"name": "crate", "shape": "cube", "size": 0.5, "motion": {"type": "dynamics", "velocity": [u, 0, 0], "restitution": 1.0, "friction": 0.0}}
    sim = run(tmp_path, [crate, _dust(speed)], 0.6, {"integrator": "rk4", "step": 1e-3, "gravity": [0, 0, 0], "air_density": 0.0})
    t = 0.6
    got = sim.particles("dust", np.array([t]))
    expected = _bounced(sim.systems["dust"].spawns.birth, t, speed, u, 0.25)
    alive = got.alive[0]
    assert alive.sum() >= 10 and (expected[alive] > 0.25 + u * t).all()
    assert np.abs(got.positions[0, alive, 0] - expected[alive]).max() < 1e-6
    assert np.abs(sim.bodies.v[:, 0] - [u, 0, 0]).max() == 0.0  # one way: the crate is not pushed


def test_particles_bounce_off_a_keyed_collider(tmp_path: Path) -> None:
    """The same against a keyed wall (a box collider moving at u): the same closed form."""
    u, speed = 2.0, 5.0
    wall = {"name": "wall", "shape": "cube", "size": 0.5, "collider": {"restitution": 1.0, "friction": 0.0},
            "motion": {"type": "keyframes", "time_unit": "seconds", "interpolation": "linear",
                       "channels": {"translate": {"keys": [{"time": 0, "value": [0, 0, 0]}, {"time": 1, "value": [u, 0, 0]}]}}}}
    sim = run(tmp_path, [wall, _dust(speed)], 0.6, {"integrator": "semi-implicit-euler", "step": 1e-3, "gravity": [0, 0, 0], "air_density": 0.0})
    got = sim.particles("dust", np.array([0.6]))
    expected = _bounced(sim.systems["dust"].spawns.birth, 0.6, speed, u, 0.25)
    alive = got.alive[0]
    assert np.abs(got.positions[0, alive, 0] - expected[alive]).max() < 1e-6


def test_validation_refuses_what_the_dynamics_stage_refuses(tmp_path: Path) -> None:
    """A collider parented to a dynamics body moves with the simulation, and an emitter
    that moves is not simulated: both are located errors when the scene loads (so `motion
    validate` exits 2, as bake and render do), not only when it is simulated."""
    body = ball("b", 1.0)
    rider = {"name": "rider", "shape": "cube", "size": 0.2, "parent": "b", "collider": {}}
    path = write_scene(tmp_path, [body, rider])
    with pytest.raises(SceneError, match=r"objects\[1\]\.collider.*cannot move with the simulation.*'b'"):
        load_scene(path)
    emitter = {"name": "dust", "shape": "particles", "radius": 0.01, "emitter": {"rate": 10},
               "motion": {"type": "keyframes", "time_unit": "seconds", "channels": {"translate": {"keys": [{"time": 0, "value": [0, 0, 0]}, {"time": 1, "value": [1, 0, 0]}]}}}}
    path = write_scene(tmp_path, [emitter], name="emit")
    with pytest.raises(SceneError, match=r"objects\[0\]\.motion.*emitter must not move"):
        load_scene(path)


def test_validate_command_exits_2_for_a_collider_on_a_body(tmp_path: Path) -> None:
    """`motion validate` said ok (exit 0) for what `motion bake` refused."""
    from _support import run_motion

    path = write_scene(tmp_path, [ball("b", 1.0), {"name": "rider", "shape": "cube", "size": 0.2, "parent": "b", "collider": {}}])
    proc = run_motion("validate", str(path))
    assert proc.returncode == 2 and "cannot move with the simulation" in proc.stderr and "Traceback" not in proc.stderr


def test_a_collider_whose_scale_is_keyed_is_a_located_error(tmp_path: Path) -> None:
    from motion.pipeline.dynamics import simulate

    lift = platform([{"time": 0, "value": [0, 0, 0]}, {"time": 1, "value": [0, 1, 0]}])
    lift["motion"]["channels"]["scale"] = {"keys": [{"time": 0, "value": [4, 0.2, 4]}, {"time": 1, "value": [5, 0.2, 4]}]}
    with pytest.raises(SceneError, match=r"objects\[1\]\.collider.*changes its size"):
        simulate(load_scene(write_scene(tmp_path, [ball("b", 2.0), lift])), 0.5)
