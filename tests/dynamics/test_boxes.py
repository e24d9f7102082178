"""True-shape contacts: rigid boxes (`shape: cube`) and cylinders against static colliders
(corners / rim points swept over the step, impulses with the angular terms)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _dynamics_scenes import apexes, floor, run
from motion.pipeline.motion.pose import quat_mul, quat_to_matrix

DYN = {"integrator": "semi-implicit-euler", "step": 0.002}
CORNERS = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], dtype=np.float64)


def body(name, shape, y, rot=None, x=0.0, **motion):
    t = {"translate": [x, y, 0]}
    if rot is not None:
        t["rotate"] = {"euler": rot}
    out = {"name": name, "shape": shape, "transform": t, "motion": {"type": "dynamics", "body": "rigid", **motion}}
    if shape == "cube":
        out["size"] = 0.2
    else:
        out.update(radius=0.1, height=0.4)
    return out


def corners_y(tr, half):
    """Height of each corner at every record, [K, 8]."""
    rot = quat_to_matrix(tr.q[:, 0])
    return tr.x[:, 0, 1][:, None] + rot[:, 1, :] @ (CORNERS * half).T


def up_angle_deg(q):
    """Angle between world up and the body axis closest to it (0: resting on a face)."""
    rot = quat_to_matrix(q)
    return math.degrees(math.acos(min(1.0, float(np.abs(rot[1, :]).max()))))


def test_cube_dropped_flat_lands_flat_and_rests(tmp_path):
    sim = run(tmp_path, [body("c", "cube", 1.0, restitution=0.5, friction=0.5), floor(restitution=0.8, friction=0.5)], 2.5, DYN)
    tr = sim.bodies
    q0 = tr.q[0, 0]
    # orientation unchanged (within 1 degree): 2 acos |q0 . q|
    dots = np.abs(tr.q[:, 0] @ q0)
    assert math.degrees(2 * math.acos(min(1.0, dots.min()))) < 1.0
    assert corners_y(tr, 0.1).min() >= -1e-9  # no corner ever below the floor
    late = tr.times > 2.0
    np.testing.assert_allclose(tr.x[late, 0, 1], 0.1, atol=1e-3)  # on its face
    assert np.ptp(tr.x[late, 0, 1]) < 1e-9  # no jitter
    assert np.abs(tr.v[late, 0]).max() < 1e-9  # at rest, no drift
    assert np.abs(tr.x[-1, 0, [0, 2]]).max() < 1e-6
    # it bounced (eps = min(0.5, 0.8)) with apexes decaying by eps^2, and energy never grew
    peaks = apexes(tr.x[:, 0, 1] - 0.1)
    assert peaks[0] == pytest.approx(0.9 * 0.25, rel=0.02)
    total = tr.kinetic + tr.potential
    assert np.diff(total).max() <= 1e-9


def test_tilted_cube_lands_on_an_edge_tips_and_settles_on_a_face(tmp_path):
    sim = run(tmp_path, [body("c", "cube", 1.0, rot=[0, 0, 30], restitution=0.3, friction=0.5), floor(restitution=0.8, friction=0.5)], 2.5, DYN)
    tr = sim.bodies
    first = tr.impacts[0]  # time, body, speed, collider, centre x, y, z
    # the first touch is a corner/edge: the centre is higher than a face landing (0.1)
    assert first[5] > 0.1 + 0.02
    assert up_angle_deg(tr.q[0, 0]) == pytest.approx(30.0, abs=1e-6)
    assert up_angle_deg(tr.q[-1, 0]) < 2.0  # it tipped onto a face
    assert corners_y(tr, 0.1).min() >= -1e-9
    late = tr.times > 2.0
    assert abs(tr.x[-1, 0, 1] - 0.1) < 1e-3
    assert np.abs(tr.v[late, 0]).max() < 1e-9
    assert np.ptp(tr.x[late, 0], axis=0).max() < 1e-9
    # energy only ever leaves (the translation that removes residual penetration may add
    # at most m g x depth: below 1e-5 of the 8.8 J dropped here)
    total = tr.kinetic + tr.potential
    assert np.diff(total).max() <= 1e-5 * abs(total[-1] - total[0])
    assert total[-1] - total[0] == pytest.approx(-9.81 * 0.9, rel=1e-3)


@pytest.mark.parametrize("mu", [0.5, 0.0])
def test_cube_slides_and_stops_with_friction_keeps_sliding_without(tmp_path, mu):
    c = body("c", "cube", 0.1 + 1e-12, velocity=[3, 0, 0], restitution=0.0, friction=mu)
    sim = run(tmp_path, [c, floor(restitution=0.0, friction=mu)], 1.2, DYN, name=f"slide{int(mu * 10)}")
    tr = sim.bodies
    assert abs(tr.x[:, 0, 1] - 0.1).max() < 1e-6  # it slides on its face, does not tip
    assert up_angle_deg(tr.q[-1, 0]) < 0.01
    if mu:
        # Coulomb: stops after v0^2 / (2 mu g), and stays stopped (no rolling like a ball)
        assert tr.x[-1, 0, 0] == pytest.approx(9 / (2 * mu * 9.81), rel=0.01)
        assert np.abs(tr.v[-1, 0]).max() < 1e-9
    else:
        np.testing.assert_allclose(tr.v[-1, 0], [3, 0, 0], atol=1e-9)
        assert tr.x[-1, 0, 0] == pytest.approx(3.6, rel=1e-6)


def test_cylinder_lands_on_its_cap_and_stays_upright(tmp_path):
    sim = run(tmp_path, [body("c", "cylinder", 1.0, restitution=0.3, friction=0.5), floor(restitution=0.8, friction=0.5)], 2.0, DYN)
    tr = sim.bodies
    axis = quat_to_matrix(tr.q[:, 0])[:, :, 1]
    assert axis[:, 1].min() > math.cos(math.radians(1.0))  # never more than 1 degree off upright
    assert tr.x[:, 0, 1].min() >= 0.2 - 1e-3
    assert abs(tr.x[-1, 0, 1] - 0.2) < 1e-3
    assert np.abs(tr.v[-50:, 0]).max() < 1e-9


def test_cylinder_on_its_side_rolls(tmp_path):
    # a solid cylinder pushed on its side ends rolling at v0 / (1 + I / (m r^2)) = 2/3 v0
    c = body("c", "cylinder", 0.1 + 1e-12, rot=[90, 0, 0], velocity=[2, 0, 0], restitution=0.0, friction=0.5)
    sim = run(tmp_path, [c, floor(restitution=0.0, friction=0.5)], 1.0, DYN)
    tr = sim.bodies
    assert abs(tr.x[:, 0, 1] - 0.1).max() < 1e-4  # on its side, on the floor
    k0, k1 = np.searchsorted(tr.times, [0.6, 0.7])
    v = tr.v[k1, 0, 0]
    assert v == pytest.approx(2 * 2 / 3, rel=0.01)
    # it rolls: the rotation rate about the cylinder axis (world z) is v / r
    dq = quat_mul(tr.q[k1, 0], tr.q[k0, 0] * np.array([1, -1, -1, -1]))
    angle = 2 * math.atan2(np.linalg.norm(dq[1:]), abs(dq[0]))
    assert angle / (tr.times[k1] - tr.times[k0]) == pytest.approx(v / 0.1, rel=0.01)
    assert abs(quat_to_matrix(tr.q[-1, 0])[2, 1]) > 0.9999  # the axis stays horizontal (along z)


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "rk4"])
def test_box_at_520_m_per_s_does_not_tunnel(tmp_path, integrator):
    # 5.2 m per 10 ms step against a 0.1 m thick box: its corners cross the plane in a step
    c = {"name": "c", "shape": "cube", "size": [0.3, 0.1, 0.2], "transform": {"translate": [0, 30, 0], "rotate": {"euler": [10, 20, 30]}},
         "motion": {"type": "dynamics", "velocity": [0, -520, 0], "restitution": 0.5}}
    sim = run(tmp_path, [c, floor(restitution=1.0)], 0.3, {"integrator": integrator, "step": 0.01})
    tr = sim.bodies
    assert corners_y(tr, np.array([0.15, 0.05, 0.1])).min() >= -1e-9
    assert len(tr.impacts) == 1 and tr.impacts[0, 2] > 500
    assert tr.v[-1, 0, 1] > 200  # bounced back up (eps 0.5)


def test_box_on_a_box_collider_and_non_uniform_size(tmp_path):
    # a 0.4 x 0.1 x 0.2 plank lands flat on a box collider (top face at y = 0.5)
    table = {"name": "table", "shape": "cube", "size": [2, 1, 2], "collider": {"restitution": 0.0, "friction": 0.5}}
    plank = {"name": "p", "shape": "cube", "size": [0.2, 0.1, 0.2], "transform": {"translate": [0.3, 1.2, 0.1], "scale": [2, 1, 1]},
             "motion": {"type": "dynamics", "restitution": 0.0, "friction": 0.5}}
    sim = run(tmp_path, [plank, table], 1.5, DYN)
    tr = sim.bodies
    assert corners_y(tr, np.array([0.2, 0.05, 0.1])).min() >= 0.5 - 1e-9
    np.testing.assert_allclose(tr.x[-1, 0], [0.3, 0.55, 0.1], atol=1e-6)
    assert np.abs(tr.v[-20:, 0]).max() < 1e-9
