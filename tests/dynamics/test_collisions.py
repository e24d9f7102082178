"""Collisions: bounces, resting contact, no tunnelling, momentum, pinned bodies, rolling,
box / sphere / mesh colliders."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _dynamics_scenes import apexes, ball, floor, run


def test_bounce_apex_heights_decay_by_eps_squared(tmp_path):
    eps = 0.8
    sim = run(tmp_path, [ball("b", 2.0, restitution=eps), floor(restitution=1.0)], 3.5, {"integrator": "rk4", "step": 0.002})
    y = sim.bodies.x[:, 0, 1] - 0.1  # height of the lowest point above the floor
    peaks = apexes(y)[:4]
    assert len(peaks) == 4
    ratios = peaks / np.concatenate(([1.9], peaks[:-1]))
    np.testing.assert_allclose(ratios, eps**2, rtol=0.01)
    # restitution is min(eps_ball, eps_floor): a less bouncy floor wins
    sim2 = run(tmp_path, [ball("b", 2.0, restitution=1.0), floor(restitution=0.5)], 1.2, {"integrator": "rk4", "step": 0.002}, name="floor_wins")
    y2 = sim2.bodies.x[:, 0, 1] - 0.1
    assert apexes(y2)[0] == pytest.approx(1.9 * 0.25, rel=0.01)


def test_ball_on_floor_comes_to_rest_without_jitter_or_energy_gain(tmp_path):
    sim = run(tmp_path, [ball("b", 0.5, restitution=0.6), floor(restitution=0.9)], 4.0, {"integrator": "semi-implicit-euler", "step": 0.002})
    tr = sim.bodies
    y = tr.x[:, 0, 1]
    assert np.all(y >= 0.1 - 1e-9)  # never inside the floor
    late = tr.times > 3.0
    np.testing.assert_allclose(y[late], 0.1, atol=1e-9)  # at rest, exactly on the floor
    assert np.abs(tr.v[late, 0]).max() < 1e-9
    total = tr.kinetic + tr.potential
    assert np.all(np.diff(total) <= 1e-9)  # contacts only ever remove energy


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_no_tunnelling_at_520_m_per_s_through_a_plane(tmp_path, integrator):
    # 520 m/s moves 5.2 m per 10 ms step: far more than the ball (r = 0.07 m) or anything
    sim = run(tmp_path, [ball("b", 30.0, radius=0.07, velocity=[0, -520, 0], restitution=0.5), floor(restitution=1.0)], 0.3, {"integrator": integrator, "step": 0.01})
    y = sim.bodies.x[:, 0, 1]
    assert y.min() >= 0.07 - 1e-9
    assert len(sim.bodies.impacts) >= 1
    assert sim.bodies.v[-1, 0, 1] > 200  # it bounced back up (eps 0.5)


def test_no_tunnelling_through_a_thin_box(tmp_path):
    plate = {"name": "plate", "shape": "cube", "size": [4, 0.002, 4], "collider": {"restitution": 0.5}, "transform": {"translate": [0, 0, 0]}}
    sim = run(tmp_path, [ball("b", 20.0, radius=0.05, velocity=[3, -520, 0], restitution=1.0), plate], 0.2, {"integrator": "rk4", "step": 0.01, "gravity": [0, -9.81, 0]})
    y = sim.bodies.x[:, 0, 1]
    assert y.min() >= 0.001 + 0.05 - 1e-9  # above the plate's top face, always
    assert sim.bodies.v[-1, 0, 1] > 200


def test_sphere_collider_and_sphere_sphere_momentum(tmp_path):
    dyn = {"integrator": "rk4", "step": 0.001, "gravity": [0, 0, 0]}
    a = ball("a", 0.05, x=-1.0, mass=1.0, velocity=[5, 0, 0], restitution=0.7, friction=0.4)
    b = ball("b", 0.0, x=1.0, mass=3.0, velocity=[-3, 0, 0], restitution=0.9, friction=0.4)
    sim = run(tmp_path, [a, b], 0.6, dyn)
    tr = sim.bodies
    p = tr.v[:, 0] * 1.0 + tr.v[:, 1] * 3.0
    np.testing.assert_allclose(p, np.broadcast_to(p[0], p.shape), rtol=0, atol=1e-12)  # momentum before = after, every step
    assert not np.allclose(tr.v[-1, 0], tr.v[0, 0])  # they did collide
    d = tr.x[:, 0] - tr.x[:, 1]
    assert np.linalg.norm(d, axis=1).min() >= 0.2 - 1e-9  # never overlapping
    # head-on: the relative normal velocity reverses times eps = min(0.7, 0.9)
    sim = run(tmp_path, [ball("a", 0.0, x=-1.0, velocity=[5, 0, 0], restitution=0.7), ball("b", 0.0, x=1.0, mass=3.0, velocity=[-3, 0, 0], restitution=0.9)], 0.6, dyn, name="headon")
    v = sim.bodies.v[-1]
    assert (v[0, 0] - v[1, 0]) == pytest.approx(-0.7 * (5 - -3), rel=1e-9)


def test_pinned_body_does_not_move(tmp_path):
    anchor = ball("anchor", 0.0, radius=0.3, pinned=True, mass=1.0, velocity=[1, 2, 3])
    dropped = ball("drop", 2.0, radius=0.1, x=0.05, restitution=0.8)
    sim = run(tmp_path, [anchor, dropped], 1.5, {"integrator": "semi-implicit-euler", "step": 0.002})
    poses = sim.sample(np.linspace(0, 1.5, 40))
    np.testing.assert_array_equal(poses["anchor"].translation, np.zeros((40, 3)))
    tr = sim.bodies
    gap = np.linalg.norm(tr.x[:, 1] - tr.x[:, 0], axis=1)
    assert gap.min() >= 0.4 - 1e-9  # it landed on the pinned ball, never inside it
    assert len(tr.impacts) >= 1
    after = np.searchsorted(tr.times, tr.impacts[0, 0]) + 1
    assert tr.v[after, 1, 1] > 0.4 * abs(tr.v[after - 2, 1, 1])  # bounced off it (eps = min(0.8, 0.5))


def test_sliding_ball_rolls_at_five_sevenths(tmp_path):
    # friction impulses at the contact point turn sliding into rolling: v = 5/7 v0 for a
    # solid sphere (I = 2/5 m r^2), whatever the friction coefficient
    b = ball("b", 0.1, velocity=[5, 0, 0], friction=0.5, restitution=0.0)
    sim = run(tmp_path, [b, floor(restitution=0.0, friction=0.5)], 2.0, {"integrator": "semi-implicit-euler", "step": 0.001})
    v = sim.bodies.v[-1, 0]
    assert v[0] == pytest.approx(5 * 5 / 7, rel=1e-3)
    pose = sim.sample(np.array([2.0]))["b"]
    assert abs(np.linalg.norm(pose.rotation[0]) - 1) < 1e-12


def test_box_on_a_slope_static_vs_kinetic_friction(tmp_path):
    # a 20 degree slope: tan(20) = 0.36; static friction 0.5 holds, 0.2 does not
    def slope(mu):
        return {"name": "slope", "shape": "rectangle", "width": 50, "height": 50, "collider": {"restitution": 0.0, "friction": mu, "static_friction": mu},
                "transform": {"rotate": {"euler": [-90, 0, 20]}}}

    n = np.array([-math.sin(math.radians(20)), math.cos(math.radians(20)), 0.0])
    start = (0.1 + 1e-12) * n
    for mu, moves in ((0.5, False), (0.2, True)):
        b = {"name": "b", "shape": "sphere", "radius": 0.1, "transform": {"translate": start.tolist()}, "motion": {"type": "dynamics", "body": "particle", "friction": mu, "static_friction": mu, "restitution": 0.0}}
        sim = run(tmp_path, [b, slope(mu)], 1.0, {"integrator": "semi-implicit-euler", "step": 0.001}, name=f"slope{int(mu * 10)}")
        travelled = np.linalg.norm(sim.bodies.x[-1, 0] - start)
        if moves:
            # kinetic: a = g (sin - mu cos), d = a t^2 / 2
            a = 9.81 * (math.sin(math.radians(20)) - mu * math.cos(math.radians(20)))
            assert travelled == pytest.approx(0.5 * a, rel=0.02)
        else:
            assert travelled < 1e-9


def test_mesh_collider_floor(tmp_path):
    (tmp_path / "ground.obj").write_text("v -5 0 -5\nv 5 0 -5\nv 5 0 5\nv -5 0 5\nf 1 2 3 4\n")
    ground = {"name": "ground", "shape": "mesh", "file": "ground.obj", "collider": {"restitution": 0.5}}
    sim = run(tmp_path, [ball("b", 1.0, x=0.3, z=-0.2, restitution=0.5), ground], 2.5, {"integrator": "semi-implicit-euler", "step": 0.002})
    y = sim.bodies.x[:, 0, 1]
    assert y.min() >= 0.1 - 1e-9
    np.testing.assert_allclose(y[-50:], 0.1, atol=1e-9)


def test_ball_rests_on_box_and_on_sphere_collider_it_rolls_off(tmp_path):
    box = {"name": "box", "shape": "cube", "size": 1.0, "collider": {"restitution": 0.0}}
    sim = run(tmp_path, [ball("b", 1.5, restitution=0.0), box], 1.5, {"integrator": "semi-implicit-euler", "step": 0.002})
    np.testing.assert_allclose(sim.bodies.x[-1, 0], [0, 0.6, 0], atol=1e-9)
    dome = {"name": "dome", "shape": "sphere", "radius": 1.0, "collider": {"restitution": 0.0}}
    sim = run(tmp_path, [ball("b", 1.5, x=0.05, restitution=0.0), dome], 3.0, {"integrator": "semi-implicit-euler", "step": 0.002}, name="dome")
    d = np.linalg.norm(sim.bodies.x[:, 0], axis=1)
    assert d.min() >= 1.1 - 1e-6
    assert sim.bodies.x[-1, 0, 1] < 0  # it rolled off the top and fell past


def test_ball_at_rest_is_held_through_coasts_as_stepping_leaves_it(tmp_path, monkeypatch):
    # one ball comes to rest early while another keeps bouncing: the coast stage holds the
    # resting one on the floor instead of stepping every body, and the result is what
    # stepping each step gives, to rounding; contacts the same, step by step
    from motion.pipeline.dynamics import step as step_module

    objects = [ball("lo", 1.0, x=-1.0, restitution=0.2), ball("hi", 2.0, x=1.0, restitution=0.9), floor(restitution=1.0)]
    dyn = {"integrator": "semi-implicit-euler", "step": 0.001}
    coasted = []
    real_coast = step_module.coast

    def counting(*args, **kwargs):
        done = real_coast(*args, **kwargs)
        coasted.append(done)
        return done

    monkeypatch.setattr(step_module, "coast", counting)
    fast = run(tmp_path, objects, 4.0, dyn, name="coasting").bodies
    monkeypatch.setattr(step_module, "coast", lambda *args, **kwargs: 0)
    slow = run(tmp_path, objects, 4.0, dyn, name="stepping").bodies
    steps = len(slow.times) - 1
    assert sum(coasted) > 0.8 * steps  # most steps coast, though "lo" rests from ~1.2 s on
    np.testing.assert_array_equal(fast.times, slow.times)
    np.testing.assert_allclose(fast.x, slow.x, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(fast.contact, slow.contact)
    assert fast.contact[-1, 0] and np.all(fast.x[fast.times > 2.0, 0, 1] == 0.1)  # at rest, on the floor


def test_mesh_collider_edges_and_corners_are_rounded(tmp_path):
    # a roof of two faces meeting at a ridge, and a pyramid's apex: a ball dropped on the
    # ridge or the apex lands on it (faces alone let it pass between them and fall through)
    (tmp_path / "tent.obj").write_text("v -1 0 -2\nv 0 1 -2\nv 0 1 2\nv -1 0 2\nv 1 0 -2\nv 1 0 2\nf 1 2 3 4\nf 2 5 6 3\n")
    (tmp_path / "pyramid.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 1 0\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n")
    dyn = {"integrator": "semi-implicit-euler", "step": 0.002}
    for mesh in ("tent", "pyramid"):
        solid = {"name": mesh, "shape": "mesh", "file": f"{mesh}.obj", "collider": {"restitution": 0.0}}
        on_top = run(tmp_path, [ball("b", 2.0, restitution=0.0), solid, floor(y=-1.0)], 1.0, dyn, name=f"{mesh}_top").bodies
        np.testing.assert_allclose(on_top.x[-1, 0], [0.0, 1.1, 0.0], atol=1e-9)  # balanced on the ridge / apex
    # just off the ridge it rolls down the +x side, never closer to the roof than its radius
    tent = {"name": "tent", "shape": "mesh", "file": "tent.obj", "collider": {"restitution": 0.0}}
    tr = run(tmp_path, [ball("b", 2.0, x=0.02, restitution=0.0), tent, floor(y=-1.0)], 1.5, dyn, name="tent_off").bodies
    x, y = tr.x[:, 0, 0], tr.x[:, 0, 1]

    def to_segment(a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
        # the roof's cross-section is the polyline (-1, 0) - (0, 1) - (1, 0): distance in x, y
        (ax, ay), (bx, by) = a, b
        u = np.clip(((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / ((bx - ax) ** 2 + (by - ay) ** 2), 0.0, 1.0)
        return np.hypot(x - ax - u * (bx - ax), y - ay - u * (by - ay))

    clearance = np.minimum(to_segment((-1, 0), (0, 1)), to_segment((0, 1), (1, 0)))
    assert clearance.min() >= 0.1 - 1e-6
    assert (clearance < 0.1 + 1e-6).sum() > 100  # it rolled on the roof, in contact
    assert x[-1] > 1.0 and y[-1] == pytest.approx(-0.9, abs=1e-9)  # off the eave, onto the floor
