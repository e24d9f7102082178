"""Rotations on the sphere: the 180-degree cube keeps its shape, slerp has constant angular
velocity along the shortest arc, `turns` spins really turn, spherical splines are C1."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from motion.pipeline.motion.keyframes import RotationTrack
from motion.pipeline.motion.pose import Pose, quat_angle, quat_conj, quat_log, quat_mul
from motion.pipeline.motion.rotation import euler_quat, key_quat
from motion.pipeline.scene.motion_schema import Channel, Key


def rtrack(keys: list[Key], mode: str = "linear", extrapolation: str = "hold") -> RotationTrack:
    return RotationTrack.compile(Channel(keys=keys), mode, extrapolation, 1.0)


CUBE = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))
EDGES = [(i, j) for i in range(8) for j in range(i + 1, 8) if np.sum(CUBE[i] != CUBE[j]) == 1]


def _volume_and_edges(vertices: np.ndarray) -> tuple[float, np.ndarray]:
    # vertex order from itertools.product: 0 = (-,-,-); 4, 2, 1 step along x, y, z
    a, b, c = vertices[4] - vertices[0], vertices[2] - vertices[0], vertices[1] - vertices[0]
    volume = float(np.dot(a, np.cross(b, c)))
    edges = np.array([np.linalg.norm(vertices[i] - vertices[j]) for i, j in EDGES])
    return volume, edges


@pytest.mark.parametrize("mode", ["linear", "catmull-rom", "bezier"])
@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 1, 0), (0.3, -1, 0.2)])
def test_cube_keyed_0_and_180_degrees_keeps_volume_and_edges(mode: str, axis: tuple[float, ...]) -> None:
    tr = rtrack([Key(time=0, axis=axis, angle=0), Key(time=1, axis=axis, angle=180)], mode)
    t = np.linspace(0.0, 1.0, 41)
    q = tr(t)
    pose = Pose(np.zeros((len(t), 3)), q, np.ones((len(t), 3)))
    verts = pose.transform_points(CUBE)
    for frame in verts:
        volume, edges = _volume_and_edges(frame)
        assert volume == pytest.approx(1.0, abs=1e-9)
        np.testing.assert_allclose(edges, 1.0, atol=1e-9)
    # it really rotated: the end pose is the 180-degree key
    np.testing.assert_allclose(np.degrees(quat_angle(q[-1], q[0])), 180.0, atol=1e-9)
    # the seed's flattening problem: lerping the vertices collapses the cube midway
    lerped = 0.5 * (verts[0] + verts[-1])
    assert abs(_volume_and_edges(lerped)[0]) < 1e-9


def test_slerp_constant_angular_velocity_matches_scipy() -> None:
    a, b = euler_quat((10, 20, 30)), euler_quat((80, -40, 100))
    tr = rtrack([Key(time=0, quaternion=tuple(a)), Key(time=2, quaternion=tuple(b))])
    t = np.linspace(0.0, 2.0, 21)
    q = tr(t)
    steps = quat_angle(q[:-1], q[1:])
    np.testing.assert_allclose(steps, steps[0], atol=1e-12)
    ref = Slerp([0.0, 2.0], Rotation.from_quat(np.stack([a, b]), scalar_first=True))(t)
    np.testing.assert_allclose(np.abs(np.sum(ref.as_quat(scalar_first=True) * q, axis=1)), 1.0, atol=1e-12)


def test_shortest_arc() -> None:
    # 0 -> 270 degrees about +Y is 90 degrees about -Y the short way
    tr = rtrack([Key(time=0, axis=(0, 1, 0), angle=0), Key(time=1, axis=(0, 1, 0), angle=270)])
    mid = tr(np.array([0.5]))[0]
    np.testing.assert_allclose(np.abs(mid), np.abs(euler_quat((0, -45, 0))), atol=1e-12)
    # sign-flipped quaternion keys (q and -q) are the same rotation: no spin at all
    q = euler_quat((0, 30, 0))
    tr = rtrack([Key(time=0, quaternion=tuple(q)), Key(time=1, quaternion=tuple(-q))])
    assert float(np.max(quat_angle(tr(np.linspace(0, 1, 11)), q))) < 1e-7


def _total_turn(q: np.ndarray) -> np.ndarray:
    """Accumulated rotation vector (in the parent frame) along a finely sampled path."""
    steps = quat_log(quat_mul(q[1:], quat_conj(q[:-1])))
    return steps.sum(axis=0)


def test_720_degree_turns_spin_turns_twice() -> None:
    tr = rtrack([Key(time=0, axis=(0, 0, 1), angle=0), Key(time=1, axis=(0, 0, 1), angle=360, turns=2)])
    q = tr(np.linspace(0.0, 1.0, 2001))
    np.testing.assert_allclose(_total_turn(q), [0, 0, 4 * np.pi], atol=1e-9)
    # quarter of the way the spin is at 180 degrees, half way back at the start orientation
    np.testing.assert_allclose(np.degrees(quat_angle(tr(np.array([0.25]))[0], q[0])), 180, atol=1e-9)
    # turns add to a non-zero shortest arc: 0 -> 90 with one extra turn is 450 degrees
    tr = rtrack([Key(time=0, euler=(0, 0, 0)), Key(time=1, euler=(0, 90, 0), turns=1)])
    np.testing.assert_allclose(np.degrees(_total_turn(tr(np.linspace(0, 1, 2001)))), [0, 450, 0], atol=1e-7)
    # and negative turns go the long way round the other way
    tr = rtrack([Key(time=0, euler=(0, 0, 0)), Key(time=1, euler=(0, 90, 0), turns=-1)])
    np.testing.assert_allclose(np.degrees(_total_turn(tr(np.linspace(0, 1, 2001)))), [0, -270, 0], atol=1e-7)


def test_turns_without_an_axis_is_an_error() -> None:
    with pytest.raises(ValueError, match="needs an axis"):
        rtrack([Key(time=0, euler=(0, 0, 0)), Key(time=1, quaternion=(1, 0, 0, 0), turns=1)])


def _angular_velocity(tr: RotationTrack, t: float, side: int, eps: float = 1e-5) -> np.ndarray:
    q = tr(np.array([t, t + side * eps, t + 2 * side * eps]))
    w1 = quat_log(quat_mul(q[1], quat_conj(q[0])))
    w2 = quat_log(quat_mul(q[2], quat_conj(q[0])))
    # second-order one-sided difference of the parent-frame rotation vector
    return side * (4 * w1 - w2) / (2 * eps)


@pytest.mark.parametrize("mode", ["catmull-rom", "bezier"])
def test_spherical_spline_passes_keys_and_is_c1(mode: str) -> None:
    eulers = [(0, 0, 0), (30, 60, 0), (90, 20, 45), (10, -50, 120), (0, 0, 0)]
    times = [0.0, 0.5, 1.7, 2.0, 3.0]
    keys = [Key(time=t, euler=e) for t, e in zip(times, eulers)]
    tr = rtrack(keys, mode)
    q = tr(np.array(times))
    for qi, e in zip(q, eulers):
        assert quat_angle(qi, euler_quat(e)) < 1e-9
    slerp = rtrack(keys, "linear")
    for t in times[1:-1]:
        np.testing.assert_allclose(_angular_velocity(tr, t, -1), _angular_velocity(tr, t, +1), atol=1e-4)
        # slerp keeps C0 only: the same check sees its kink
        assert np.linalg.norm(_angular_velocity(slerp, t, -1) - _angular_velocity(slerp, t, +1)) > 0.1


def test_rotation_extrapolation() -> None:
    keys = [Key(time=0, axis=(0, 1, 0), angle=0), Key(time=1, axis=(0, 1, 0), angle=90)]
    lin = rtrack(keys, "linear", "linear")
    np.testing.assert_allclose(np.abs(lin(np.array([2.0]))[0]), np.abs(euler_quat((0, 180, 0))), atol=1e-12)
    cyc = rtrack(keys, "linear", "cycle")
    np.testing.assert_allclose(cyc(np.array([1.25])), cyc(np.array([0.25])), atol=1e-12)
    hold = rtrack(keys, "linear", "hold")
    np.testing.assert_allclose(hold(np.array([-1.0, 5.0])), np.stack([key_quat(keys[0]), key_quat(keys[1])]), atol=1e-12)


def test_rotation_forms_agree() -> None:
    expect = euler_quat((90, 0, 0))
    for key in (
        Key(time=0, value=(90.0, 0.0, 0.0)),
        Key(time=0, euler=(90, 0, 0), order="xyz"),
        Key(time=0, axis=(2, 0, 0), angle=90),
        Key(time=0, quaternion=(2 * expect[0], 2 * expect[1], 0, 0)),
    ):
        assert quat_angle(key_quat(key), expect) < 1e-12
    # intrinsic vs extrinsic orders differ as scipy defines them
    assert quat_angle(euler_quat((90, 90, 0), "XYZ"), euler_quat((90, 90, 0), "xyz")) > 0.1


def test_euler_and_matrix_conversions_are_scipys_to_the_last_bit_and_sign() -> None:
    """motion/rotation.py converts Euler angles (all 12 orders, extrinsic and intrinsic) and
    matrices with numpy instead of importing scipy.spatial (0.15 s per process): the same
    quaternions as scipy's Rotation, sign included, to 1 ulp."""
    import itertools

    from scipy.spatial.transform import Rotation

    from motion.pipeline.motion.rotation import euler_quat, matrix_quat

    rng = np.random.default_rng(7)
    orders = ["".join(p) for p in itertools.product("xyz", repeat=3) if p[0] != p[1] and p[1] != p[2]]
    for order in orders + [o.upper() for o in orders]:
        for angles in rng.uniform(-400, 400, (50, 3)):
            ref = Rotation.from_euler(order, angles, degrees=True).as_quat(scalar_first=True)
            assert np.abs(euler_quat(angles, order) - ref).max() <= 4.5e-16, (order, angles)
    for m in Rotation.random(500, rng=rng).as_matrix():
        assert np.abs(matrix_quat(m) - Rotation.from_matrix(m).as_quat(scalar_first=True)).max() <= 4.5e-16
