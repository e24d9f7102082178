"""Joints: pendulum periods on a rod and a pin (closed forms), a hinge keeps the rotation
about its axis only, hinge limits, a rope is slack below its length and holds it taut,
breaking forces, joints between two bodies, and located errors for bad joints."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.special import ellipk

from _dynamics_scenes import ball, run, write_scene
from motion.pipeline.dynamics import simulate
from motion.pipeline.errors import SceneError
from motion.pipeline.motion.pose import quat_to_matrix
from motion.pipeline.scene import load_scene

G = 9.81
INTEGRATORS = ["euler", "semi-implicit-euler", "midpoint", "heun", "rk4", "rk45"]


def _period(t: np.ndarray, x: np.ndarray) -> float:
    """Mean time between upward zero crossings of x(t) (linear interpolation)."""
    k = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[k] - x[k] * (t[k + 1] - t[k]) / (x[k + 1] - x[k])
    return float(np.diff(crossings).mean())


def _hung(theta0: float, length: float, radius: float = 0.01, **motion: object) -> dict:
    """A ball hanging from the origin at angle theta0 from the vertical."""
    return ball("bob", -length * math.cos(theta0), x=length * math.sin(theta0), radius=radius, friction=0.0, **motion)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_point_mass_on_a_rod_swings_at_the_pendulum_period(tmp_path: Path, integrator: str) -> None:
    """A point mass (`body: particle`) on a distance joint of length L: small-angle period
    2 pi sqrt(L/g) within 0.1 % (and the exact finite-amplitude period 4 sqrt(L/g)
    K(sin^2(theta0/2)) within 1e-4), the rod's length held to 1e-12 L."""
    L, theta0 = 1.0, 0.02
    sim = run(tmp_path, [_hung(theta0, L, body="particle")], 4.5,
              {"integrator": integrator, "step": 2e-3, "air_density": 0.0, "joints": [{"type": "distance", "a": "bob", "anchor": [0, 0, 0]}]})
    tr = sim.bodies
    T = _period(tr.times, tr.x[:, 0, 0])
    assert abs(T / (2 * math.pi * math.sqrt(L / G)) - 1) < 1e-3
    assert abs(T / (4 * math.sqrt(L / G) * ellipk(math.sin(theta0 / 2) ** 2)) - 1) < 1e-4
    assert np.abs(np.linalg.norm(tr.x[:, 0], axis=1) - L).max() < 1e-12 * L


@pytest.mark.slow  # about 40 s per integrator on a busy 2-core host: CI's second step
@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_a_ball_on_a_pin_swings_as_a_physical_pendulum(tmp_path: Path, integrator: str) -> None:
    """A rigid ball (radius r) pinned at the origin, L from its centre: it turns with its
    swing, so the period is 2 pi sqrt((L^2 + 2/5 r^2) / (g L)) (the point-mass period within
    0.1 % for r = 0.01 L); the pivot is held within 1e-4 L."""
    L, r, theta0 = 1.0, 0.01, 0.02
    sim = run(tmp_path, [_hung(theta0, L, radius=r)], 4.5,
              {"integrator": integrator, "step": 1e-3, "air_density": 0.0, "joints": [{"type": "pin", "a": "bob", "anchor": [0, 0, 0]}]})
    tr = sim.bodies
    T = _period(tr.times, tr.x[:, 0, 0])
    assert abs(T / (2 * math.pi * math.sqrt(L / G)) - 1) < 1e-3
    assert abs(T / (4 * math.sqrt((L * L + 0.4 * r * r) / (G * L)) * ellipk(math.sin(theta0 / 2) ** 2)) - 1) < 1e-4
    R = quat_to_matrix(tr.q[:, 0])
    pivot = tr.x[:, 0] + np.einsum("kij,j->ki", R, np.array([-L * math.sin(theta0), L * math.cos(theta0), 0.0]))
    assert np.abs(pivot).max() < 1e-4 * L


def _door(**motion: object) -> dict:
    """A 1 x 2 x 0.1 m door, its left edge on the Y axis."""
    return {"name": "door", "shape": "cube", "size": 1.0, "transform": {"translate": [0.5, 0, 0], "scale": [1, 2, 0.1]},
            "motion": {"type": "dynamics", **motion}}


@pytest.mark.parametrize("integrator,seconds", [pytest.param("rk4", 10.0, marks=pytest.mark.slow), ("semi-implicit-euler", 2.0)])  # the 10 s run: CI's second step
def test_a_hinge_keeps_the_rotation_about_its_axis_only(tmp_path: Path, integrator: str, seconds: float) -> None:
    """A door on a hinge about +Y at its edge, launched spinning about a tilted axis and
    moving sideways: after 10 s its Y axis is still the hinge's (off-axis angle < 1e-6 rad)
    and its hinge edge is still on the axis; it turns about Y."""
    door = _door(angular_velocity=[30, 200, 40], velocity=[0, 0, 1])
    sim = run(tmp_path, [door], seconds, {"integrator": integrator, "step": 2e-3, "air_density": 0.0,
                                          "joints": [{"type": "hinge", "a": "door", "anchor": [0, 0, 0], "axis": [0, 1, 0]}]})
    tr = sim.bodies
    R = quat_to_matrix(tr.q[:, 0])
    off_axis = np.arctan2(np.linalg.norm(np.cross(R[:, :, 1], [0.0, 1.0, 0.0]), axis=1), R[:, 1, 1])
    assert off_axis.max() < 1e-6
    edge = tr.x[:, 0] + np.einsum("kij,j->ki", R, np.array([-0.5, 0.0, 0.0]))
    assert np.abs(edge[:, [0, 2]]).max() < 1e-9 and np.abs(edge[:, 1]).max() < 1e-9
    turned = np.arctan2(-R[:, 2, 0], R[:, 0, 0])
    assert np.ptp(np.unwrap(turned)) > 1.0  # it swung about the hinge


def test_hinge_limits_stop_the_door(tmp_path: Path) -> None:
    """Limits [-30, 45] degrees: a door spun at 200 degrees/s about its hinge stops at 45
    and stays within the range (to 1e-6 rad)."""
    sim = run(tmp_path, [_door(angular_velocity=[0, 200, 0])], 1.5,
              {"integrator": "rk4", "step": 2e-3, "gravity": [0, 0, 0], "joints": [{"type": "hinge", "a": "door", "anchor": [0, 0, 0], "axis": [0, 1, 0], "limits": [-30, 45]}]})
    R = quat_to_matrix(sim.bodies.q[:, 0])
    angle = np.arctan2(-R[:, 2, 0], R[:, 0, 0])
    assert angle.max() <= math.radians(45) + 1e-6 and angle.min() >= math.radians(-30) - 1e-6
    assert angle.max() > math.radians(45) - 1e-6  # it reached the stop


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_a_rope_is_slack_below_its_length_and_holds_it_taut(tmp_path: Path, integrator: str) -> None:
    """A ball tied by a 2 m rope to a point 1 m above it falls freely (the closed form, to
    rounding) until the rope is taut, then swings on it: its length within 1e-4 L."""
    L = 2.0
    sim = run(tmp_path, [ball("b", -1.0, x=0.0, radius=0.05, friction=0.0, velocity=[1.0, 0, 0])], 2.0,
              {"integrator": integrator, "step": 1e-3, "air_density": 0.0, "joints": [{"type": "rope", "a": "b", "anchor": [0, 0, 0], "length": L}]})
    tr = sim.bodies
    dist = np.linalg.norm(tr.x[:, 0], axis=1)
    slack = np.flatnonzero(dist < L * (1 - 1e-6))
    first_taut = int(np.argmax(dist >= L * (1 - 1e-6)))
    assert first_taut > 0 and slack.size
    free = np.arange(first_taut)
    t = tr.times[free]
    expected = np.stack((t, -1.0 - 0.5 * G * t * t), axis=1)
    c = {"rk4": 0.5, "semi-implicit-euler": None}[integrator]
    if c is not None:  # exact under RK4; semi-implicit Euler has its own h t / 2 offset
        assert np.abs(tr.x[free, 0, :2] - expected).max() < 1e-9
    assert dist.max() < L * (1 + 1e-4)
    assert dist[first_taut:].min() > 0.9 * L  # it swings on the rope (no bounce back in)


def test_a_joint_breaks_past_its_breaking_force(tmp_path: Path) -> None:
    """A 1 kg ball hanging on a rope pulls m g = 9.81 N: a 20 N rope holds it, a 5 N rope
    breaks on the first step and the ball falls freely."""
    hang = ball("b", -1.0, radius=0.05)
    held = run(tmp_path, [hang], 0.5, {"integrator": "rk4", "step": 1e-3, "air_density": 0.0,
                                       "joints": [{"type": "rope", "a": "b", "anchor": [0, 0, 0], "break_force": 20.0}]})
    assert abs(held.bodies.x[-1, 0, 1] + 1.0) < 1e-9
    broke = run(tmp_path, [hang], 0.5, {"integrator": "rk4", "step": 1e-3, "air_density": 0.0,
                                        "joints": [{"type": "rope", "a": "b", "anchor": [0, 0, 0], "break_force": 5.0}]})
    t = broke.bodies.times[-1]
    assert abs(broke.bodies.x[-1, 0, 1] - (-1.0 - 0.5 * G * (t - 1e-3) ** 2)) < 0.02


def test_a_rod_between_two_bodies_keeps_its_length_and_their_momentum(tmp_path: Path) -> None:
    """Two balls (1 and 3 kg) on a 1 m rod, thrown spinning in free space: the rod holds 1 m
    (1e-12), the total momentum is kept (1e-12), the centre of mass moves in a line."""
    a = ball("a", 0.0, x=-0.5, radius=0.05, mass=1.0, velocity=[0, 2, 0])
    b = ball("b", 0.0, x=0.5, radius=0.05, mass=3.0, velocity=[0, -1, 1])
    sim = run(tmp_path, [a, b], 2.0, {"integrator": "rk4", "step": 1e-3, "gravity": [0, 0, 0], "air_density": 0.0,
                                      "joints": [{"type": "distance", "a": "a", "b": "b"}]})
    x, v = sim.bodies.x, sim.bodies.v
    assert np.abs(np.linalg.norm(x[:, 0] - x[:, 1], axis=1) - 1.0).max() < 1e-12
    p = v[:, 0] + 3.0 * v[:, 1]
    assert np.abs(p - p[0]).max() < 1e-12
    com = (x[:, 0] + 3.0 * x[:, 1]) / 4.0
    assert np.abs(com - (com[0] + np.outer(sim.bodies.times, p[0] / 4.0))).max() < 1e-9


WRECKING_BALL = """
  joints:
    - type: rope
      a: wrecking_ball
      anchor: [0, 12, 0]
"""


def test_the_wrecking_ball_example_of_the_docs_loads_and_swings(tmp_path: Path) -> None:
    """docs/dynamics.md's wrecking ball: a ball on a rope in four lines of YAML. It swings
    on the rope (length 8 m, its initial distance) through the bottom of its arc."""
    docs = (Path(__file__).resolve().parents[2] / "docs" / "dynamics.md").read_text()
    block = re.search(r"```yaml\n(dynamics:\n  joints:\n(?:.*\n)*?)```", docs)
    assert block is not None, "the wrecking-ball example is in docs/dynamics.md"
    joints = yaml.safe_load(block.group(1))["dynamics"]["joints"]
    assert len(block.group(1).strip().splitlines()) == 6  # dynamics:, joints: and the joint's four lines
    obj = {"name": "wrecking_ball", "shape": "sphere", "radius": 0.5, "transform": {"translate": [8 * math.sin(0.5), 12 - 8 * math.cos(0.5), 0]},
           "motion": {"type": "dynamics", "mass": 500}}
    sim = simulate(load_scene(write_scene(tmp_path, [obj], {"joints": joints, "step": 2e-3})), 1.5)
    dist = np.linalg.norm(sim.bodies.x[:, 0] - [0, 12, 0], axis=1)
    assert np.abs(dist - 8.0).max() < 1e-4 * 8.0
    assert sim.bodies.x[:, 0, 0].min() < 0.0  # it swung through the bottom


@pytest.mark.parametrize("joint,message", [
    ({"type": "pin", "a": "bobb", "anchor": [0, 0, 0]}, r"joints\[0\]\.a.*'bobb' is not a dynamics body.*bob"),
    ({"type": "rope", "a": "bob", "b": "wall", "length": 1}, r"joints\[0\]\.b.*'wall' is not a dynamics body"),
    ({"type": "hinge", "a": "bob", "anchor": [0, 0, 0], "axis": [0, 0, 0]}, r"joints\[0\].*axis must not be zero"),
    ({"type": "hinge", "a": "bob", "anchor": [0, 0, 0]}, r"joints\[0\].*needs an axis"),
    ({"type": "rope", "a": "bob", "anchor": [0, 0, 0], "length": -1}, r"joints\[0\]\.length"),
    ({"type": "distance", "a": "bob", "anchor": [0, ".nan", 0]}, r"joints\[0\]\.anchor"),
    ({"type": "pin", "a": "bob"}, r"joints\[0\].*needs an anchor"),
    ({"type": "distance", "a": "bob", "b": "bob"}, r"joints\[0\].*two different bodies"),
    ({"type": "hinge", "a": "bob", "anchor": [0, 0, 0], "axis": [0, 1, 0], "limits": [30, -30]}, r"joints\[0\].*limits"),
])
def test_bad_joints_are_located_errors(tmp_path: Path, joint: dict, message: str) -> None:
    path = write_scene(tmp_path, [ball("bob", 0.0)], {"joints": [joint]})
    text = path.read_text().replace("'.nan'", ".nan")
    path.write_text(text)
    with pytest.raises(SceneError, match=message):
        load_scene(path)


def test_the_number_of_joints_is_bounded(tmp_path: Path) -> None:
    joints = [{"type": "rope", "a": "bob", "anchor": [0, 0, 0]}] * 10_001
    with pytest.raises(SceneError, match=r"dynamics\.joints"):
        load_scene(write_scene(tmp_path, [ball("bob", 0.0)], {"joints": joints}))
