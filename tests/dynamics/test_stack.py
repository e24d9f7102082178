"""Boxes on boxes: the "ten books" stack at rest, with impulses (box-box manifolds solved
across bodies, island.py) and with penalty contacts (anchored static friction, capped
dampers, penalty.py); friction on an incline and momentum in box-box collisions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _dynamics_scenes import floor, run

SIZE, MASS, MU, G = 0.2, 1.0, 0.5, 9.81
N = 10


def box(name: str, y: float, x: float = 0.0, size: float | list[float] = SIZE, **motion) -> dict:
    """A rigid dynamics box at (x, y, 0)."""
    spec = {"type": "dynamics", "body": "rigid", "mass": MASS, "restitution": 0.0, "friction": MU, **motion}
    return {"name": name, "shape": "cube", "size": size, "transform": {"translate": [x, y, 0]}, "motion": spec}


def stack(heights: np.ndarray, **motion) -> list[dict]:
    """Boxes at the given centre heights, on a floor."""
    return [box(f"b{k}", float(y), **motion) for k, y in enumerate(heights)] + [floor(restitution=0.0, friction=MU)]


def at_rest(tr, bound: float = 1e-4) -> tuple[float, float]:
    """The largest displacement of any box from its start, and the largest peak-to-peak
    motion (jitter) of any box coordinate over the second half of the run."""
    drift = float(np.linalg.norm(tr.x - tr.x[0], axis=2).max())
    late = tr.times >= 0.5 * tr.times[-1]
    jitter = float(np.ptp(tr.x[late], axis=0).max())
    return drift, jitter


# --- impulses -------------------------------------------------------------------------------


def _impulse_stack(tmp_path, integrator: str, t_end: float, gap: float) -> None:
    heights = SIZE / 2 + gap + np.arange(N) * (SIZE + gap)
    sim = run(tmp_path, stack(heights), t_end, {"integrator": integrator, "step": 0.002}, name=f"stack_{integrator}")
    tr = sim.bodies
    drift, jitter = at_rest(tr)
    # every box stays where it was put (gaps of 1 um close; before, the boxes met as bounding
    # spheres and the stack flew apart at once)
    assert drift <= 1e-4 and jitter <= 1e-4, (drift, jitter)
    np.testing.assert_allclose(tr.x[-1, :, 1], SIZE / 2 + np.arange(N) * SIZE, atol=1e-4)
    assert np.abs(tr.v[-1]).max() < 1e-3


def test_ten_boxes_stay_stacked_with_impulses(tmp_path):
    _impulse_stack(tmp_path, "rk4", 0.5, 1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["rk4", "semi-implicit-euler", "midpoint", "heun"])
def test_ten_boxes_stay_stacked_for_10_s_with_impulses(tmp_path, integrator):
    _impulse_stack(tmp_path, integrator, 10.0, 0.0)


def test_box_dropped_on_a_box_settles_on_it(tmp_path):
    objs = [box("low", SIZE / 2), box("high", 1.0, x=0.03, restitution=0.3)] + [floor(restitution=0.0, friction=MU)]
    sim = run(tmp_path, objs, 1.5, {"integrator": "rk4", "step": 0.002})
    tr = sim.bodies
    # it lands flat on the lower box's top face and stays there; the lower box does not move
    assert tr.x[:, 1, 1].min() >= 1.5 * SIZE - 1e-4
    np.testing.assert_allclose(tr.x[-1, 1], [0.03, 1.5 * SIZE, 0.0], atol=1e-4)
    assert np.linalg.norm(tr.x[:, 0] - tr.x[0, 0], axis=1).max() < 1e-4
    late = tr.times > 1.0
    assert np.ptp(tr.x[late], axis=0).max() < 1e-6


@pytest.mark.parametrize("degrees", [20.0, 30.0])
def test_two_stacked_boxes_on_an_incline_stick_or_slide_by_tan_theta(tmp_path, degrees):
    # an incline of theta as gravity turned by theta over a level floor: the pair holds iff
    # tan(theta) < mu (0.36 < 0.5 holds; 0.58 > 0.5 slides), and slides together at
    # a = g (sin theta - mu cos theta) (the top box has more friction: it rides along).
    # Flat boxes (0.4 x 0.1 x 0.2): the sliding pair's normal force moves mu H / 2 = 0.05 m
    # forward, well inside its 0.2 m half base (a cube pair would be at the tipping point)
    th = math.radians(degrees)
    gravity = [G * math.sin(th), -G * math.cos(th), 0.0]
    flat = [0.4, 0.1, 0.2]
    objs = [box("low", 0.05, size=flat), box("high", 0.15, size=flat, friction=1.0), floor(restitution=0.0, friction=MU)]
    sim = run(tmp_path, objs, 1.0, {"integrator": "rk4", "step": 0.002, "gravity": gravity}, name=f"incline{int(degrees)}")
    tr = sim.bodies
    np.testing.assert_allclose(tr.x[:, :, 1], tr.x[:1, :, 1].repeat(len(tr.times), 0), atol=1e-4)  # nothing tips or lifts
    gap = tr.x[:, 1, 0] - tr.x[:, 0, 0]
    assert np.abs(gap - gap[0]).max() < 1e-4  # the top box rides on the bottom one
    if math.tan(th) < MU:
        assert np.abs(tr.x[:, 0, 0] - tr.x[0, 0, 0]).max() < 1e-4
    else:
        a = G * (math.sin(th) - MU * math.cos(th))
        assert tr.x[-1, 0, 0] - tr.x[0, 0, 0] == pytest.approx(0.5 * a * tr.times[-1] ** 2, rel=0.01)


@pytest.mark.parametrize("restitution", [1.0, 0.0])
def test_box_box_collision_keeps_momentum(tmp_path, restitution):
    # 1 kg at +2 m/s meets 2 kg at -1 m/s face on, no gravity: momentum 0 is kept, and the
    # velocities after are the 1D closed form v1' = ((m1 - e m2) v1 + (1 + e) m2 v2) / (m1 + m2)
    a = box("a", 0.0, x=-0.5, velocity=[2, 0, 0], restitution=restitution)
    b = box("b", 0.0, x=0.5, velocity=[-1, 0, 0], restitution=restitution, mass=2.0)
    sim = run(tmp_path, [a, b], 1.0, {"integrator": "rk4", "step": 0.002, "gravity": [0, 0, 0]}, name=f"hit{int(restitution)}")
    tr = sim.bodies
    p = tr.v[:, 0] * 1.0 + tr.v[:, 1] * 2.0
    assert np.abs(p).max() < 1e-12
    e, m1, m2, v1, v2 = restitution, 1.0, 2.0, 2.0, -1.0
    expect_a = ((m1 - e * m2) * v1 + (1 + e) * m2 * v2) / (m1 + m2)
    expect_b = ((m2 - e * m1) * v2 + (1 + e) * m1 * v1) / (m1 + m2)
    np.testing.assert_allclose(tr.v[-1, 0], [expect_a, 0, 0], atol=1e-9)
    np.testing.assert_allclose(tr.v[-1, 1], [expect_b, 0, 0], atol=1e-9)
    np.testing.assert_allclose(np.abs(tr.q[-1, :, 0]), 1.0, atol=1e-12)  # face on: no spin
    assert tr.x[-1, 1, 0] - tr.x[-1, 0, 0] >= SIZE - 1e-9  # never inside each other at the end


# --- penalty contacts -----------------------------------------------------------------------


def _penalty_equilibrium(k: float) -> np.ndarray:
    """Centre heights of the stack resting on its springs: the floor's 4 corners carry
    N m g (each k), and each box-box face 8 points (4 of each box's face into the other) of
    k/2 each (two bodies' springs in series), 4k in all, carrying the boxes above it."""
    load = (N - np.arange(N)) * MASS * G / (4.0 * k)  # the compression of each level
    return SIZE / 2 + np.arange(N) * SIZE - np.cumsum(load)


def _penalty_stack(tmp_path, integrator: str, t_end: float) -> None:
    # the default penalty contact (10 ms, restitution 0: critical damping), at h = T / 20
    k = MASS * (math.pi / 0.01) ** 2
    heights = _penalty_equilibrium(k)
    sim = run(tmp_path, stack(heights, contact="penalty"), t_end, {"integrator": integrator, "step": 0.0005}, name=f"pstack_{integrator}")
    tr = sim.bodies
    drift, jitter = at_rest(tr)
    # at rest where the closed form puts it (before, the dampers of the stack, in series,
    # were past the explicit step's bound and the stack bounced and crept sideways)
    assert drift <= 1e-4 and jitter <= 1e-4, (drift, jitter)


def test_ten_boxes_stay_stacked_with_penalty_contacts(tmp_path):
    _penalty_stack(tmp_path, "semi-implicit-euler", 0.3)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_ten_boxes_stay_stacked_for_10_s_with_penalty_contacts(tmp_path, integrator):
    _penalty_stack(tmp_path, integrator, 10.0)


def test_penalty_box_holds_on_an_incline_below_the_friction_angle(tmp_path):
    # tan(20 deg) = 0.36 < mu = 0.5: static friction holds the box where it settled. Its
    # spring, anchored where the contact stuck, takes the slope's pull with a fixed
    # stretch; before, friction capped per step let it creep down the slope
    th = math.radians(20.0)
    k = MASS * (math.pi / 0.01) ** 2
    objs = [box("b", SIZE / 2 - MASS * G * math.cos(th) / (4 * k), contact="penalty"), floor(restitution=0.0, friction=MU)]
    sim = run(tmp_path, objs, 1.0, {"integrator": "semi-implicit-euler", "step": 0.0005, "gravity": [G * math.sin(th), -G * math.cos(th), 0.0]})
    tr = sim.bodies
    late = tr.times > 0.5
    assert np.ptp(tr.x[late, 0, 0]) < 1e-7  # it holds: no creep after it settled
    # where it settled: the anchored springs' stretch under the slope's pull over 4 corners
    # of k_t = 2/7 k (30 um), plus what it slid before its springs took hold (20 um)
    stretch = MASS * G * math.sin(th) / (4 * 2 / 7 * k)
    assert stretch <= tr.x[-1, 0, 0] <= stretch + 1e-4


def test_a_sleeping_stack_wakes_when_hit(tmp_path):
    # three boxes fall asleep (calm for 0.5 s: held at rest); at 1 s a box released beside
    # the top one at 3 m/s hits its side face: the set wakes and the top box is knocked
    # along, the bottom one (held by the floor's friction) barely
    heights = SIZE / 2 + np.arange(3) * SIZE
    hit = box("hit", 2.5 * SIZE, x=-1.25 * SIZE, velocity=[3, 0, 0], start=1.0)
    sim = run(tmp_path, stack(heights) + [hit], 1.4, {"integrator": "rk4", "step": 0.002}, name="wake")
    tr = sim.bodies
    before = tr.times < 1.0
    assert np.linalg.norm(tr.x[before, :3] - tr.x[0, :3], axis=2).max() < 1e-6  # asleep and still
    assert np.abs(tr.v[(tr.times > 0.6) & before, :3]).max() == 0.0  # held at rest
    assert tr.x[-1, 2, 0] - tr.x[0, 2, 0] > 1e-3  # the top box was dragged
    assert abs(tr.x[-1, 0, 0] - tr.x[0, 0, 0]) < 1e-3
