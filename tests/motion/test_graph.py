"""Parent frames: a depth-3 chain against hand-composed matrices, a camera riding a moving
object, evaluation order, dynamics needing a simulation, the example scenes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion.pipeline.motion import Pose, SimulationRequiredError, evaluate
from motion.pipeline.motion.graph import ParentCycleError, evaluation_order
from motion.pipeline.motion.pose import quat_angle
from motion.pipeline.scene import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"

CHAIN = """
camera:
  position: [0, 0, 3]
  look_at: [0, 0, 0]
  parent: c
objects:
  - name: d
    shape: sphere
    parent: c
    transform: {translate: [0, 0, 0.4], rotate: {quaternion: [0.9, 0.1, 0.3, 0.2]}, scale: 0.5}
  - name: a
    shape: empty
    transform: {translate: [1, 2, 3], scale: 2}
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate: {keys: [{time: 0, value: [0, 0, 0]}, {time: 1, value: [4, 0, -2]}]}
        rotate: {keys: [{time: 0, euler: [0, 0, 0]}, {time: 1, euler: [0, 90, 0]}]}
  - name: b
    shape: empty
    parent: a
    transform: {translate: [1, 0, 0], rotate: {axis: [1, 0, 0], angle: 30}, scale: 1.5}
  - name: c
    shape: cube
    parent: b
    transform: {translate: [0, 1, 0.5], rotate: {euler: [10, 20, 30], order: ZYX}}
"""


def matrix(translate, quat_wxyz, scale) -> np.ndarray:  # type: ignore[no-untyped-def]
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(quat_wxyz, scalar_first=True).as_matrix() @ np.diag(np.broadcast_to(scale, 3))
    m[:3, 3] = translate
    return m


def _load(tmp_path: Path, text: str):  # type: ignore[no-untyped-def]
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return load_scene(path)


def test_parent_chain_depth_3_matches_hand_composed_matrices(tmp_path: Path) -> None:
    times = np.array([0.0, 0.3, 0.75, 1.0])
    m = evaluate(_load(tmp_path, CHAIN), times)
    for k, t in enumerate(times):
        # a: keyed translate and slerped rotation about +Y (replacing the transform's), scale 2
        a = matrix([4 * t, 0, -2 * t], Rotation.from_euler("y", 90 * t, degrees=True).as_quat(scalar_first=True), 2)
        b = matrix([1, 0, 0], Rotation.from_rotvec([np.radians(30), 0, 0]).as_quat(scalar_first=True), 1.5)
        c = matrix([0, 1, 0.5], Rotation.from_euler("ZYX", [10, 20, 30], degrees=True).as_quat(scalar_first=True), 1)
        q = np.array([0.9, 0.1, 0.3, 0.2])
        d = matrix([0, 0, 0.4], q / np.linalg.norm(q), 0.5)
        expect = {"a": a, "b": a @ b, "c": a @ b @ c, "d": a @ b @ c @ d}
        for name, mat in expect.items():
            np.testing.assert_allclose(m.objects[name].matrices()[k], mat, atol=1e-12, err_msg=f"{name} at t={t}")
        # the camera rides on c: world_from_camera = world_from_c * c_from_camera
        cam_local = np.linalg.inv(c) @ np.linalg.inv(b) @ np.linalg.inv(a) @ m.camera.matrices()[k]
        # Mitsuba's look_at from (0, 0, 3) to the origin: +Z forward = -z, +Y up, +X left = -x
        np.testing.assert_allclose(cam_local, matrix([0, 0, 3], Rotation.from_matrix(np.diag([-1.0, 1.0, -1.0])).as_quat(scalar_first=True), 1), atol=1e-12)


CAMERA_ON_CAR = """
camera:
  parent: car
  position: [0, 1.5, -4]
  look_at: [0, 1, 0]
objects:
  - name: car
    shape: cube
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate: {keys: [{time: 0, value: [0, 0, 0]}, {time: 2, value: [10, 0, 0]}]}
        rotate: {keys: [{time: 0, euler: [0, 0, 0]}, {time: 2, euler: [0, 90, 0]}]}
"""


def test_camera_parented_to_a_moving_object(tmp_path: Path) -> None:
    times = np.linspace(0.0, 2.0, 5)
    m = evaluate(_load(tmp_path, CAMERA_ON_CAR), times)
    car = m.objects["car"]
    # the camera keeps its offset in the car's frame and turns with it
    offset = Rotation.from_quat(car.rotation, scalar_first=True).apply([0, 1.5, -4])
    np.testing.assert_allclose(m.camera.translation, car.translation + offset, atol=1e-12)
    rel = quat_angle(m.camera.rotation, m.camera.rotation[0:1])
    np.testing.assert_allclose(np.degrees(rel), np.degrees(quat_angle(car.rotation, car.rotation[0:1])), atol=1e-9)
    # the camera looks at the car's roof: local +Z points at car + (0, 1, 0)
    forward = Rotation.from_quat(m.camera.rotation, scalar_first=True).apply([0, 0, 1])
    target = car.translation + Rotation.from_quat(car.rotation, scalar_first=True).apply([0, 1, 0])
    to_target = target - m.camera.translation
    np.testing.assert_allclose(forward, to_target / np.linalg.norm(to_target, axis=1, keepdims=True), atol=1e-12)
    assert not np.allclose(m.camera.translation[0], m.camera.translation[-1])


def test_scale_composes_component_wise(tmp_path: Path) -> None:
    text = """
camera: {position: [0, 0, 3], look_at: [0, 0, 0]}
objects:
  - {name: p, shape: empty, transform: {scale: [1, 2, 3]}}
  - {name: c, shape: sphere, parent: p, transform: {translate: [1, 1, 1], scale: [2, 2, 2]}}
"""
    m = evaluate(_load(tmp_path, text), np.zeros(1))
    np.testing.assert_allclose(m.objects["c"].scale, [[2, 4, 6]])
    np.testing.assert_allclose(m.objects["c"].translation, [[1, 2, 3]])


def test_evaluation_order_and_cycles() -> None:
    order = evaluation_order({"d": "c", "a": None, "c": "b", "b": "a", "e": None})
    assert order.index("a") < order.index("b") < order.index("c") < order.index("d")
    with pytest.raises(ParentCycleError, match="parent cycle"):
        evaluation_order({"a": "b", "b": "a"})


def test_dynamics_scene_needs_a_simulation() -> None:
    loaded = load_scene(SCENES / "bouncing-balls.yaml")
    with pytest.raises(SimulationRequiredError, match="ball_hi"):
        evaluate(loaded, np.zeros(2))

    class FakeSimulation:
        """Test double: a fixed pose per body, to check evaluate routes dynamics through sample()."""

        def __init__(self) -> None:
            self.asked: list[np.ndarray] = []

        def sample(self, times: np.ndarray) -> dict[str, Pose]:
            self.asked.append(times)
            n = len(times)
            out = {}
            for i, name in enumerate(("ball_hi", "ball_mid", "ball_lo")):
                tr = np.zeros((n, 3))
                tr[:, 0] = i
                tr[:, 1] = times
                out[name] = Pose(tr, np.tile([1.0, 0, 0, 0], (n, 1)), np.ones((n, 3)))
            return out

    sim = FakeSimulation()
    m = evaluate(loaded, np.array([0.0, 0.5]), simulation=sim)
    np.testing.assert_allclose(m.objects["ball_lo"].translation, [[2, 0, 0], [2, 0.5, 0]])
    assert len(sim.asked) == 1


def test_example_scenes_evaluate() -> None:
    walk = load_scene(SCENES / "walk-cycle.yaml")
    t = np.linspace(0.0, 2.0, 49)
    m = evaluate(walk, t)
    hips = m.objects["hips"].translation
    np.testing.assert_allclose(hips[:, 0], 1.2 * t, atol=1e-12)  # the root keeps walking
    # the 4-pose cycle repeats every second, in world space relative to the hips
    rel = m.objects["leg_l"].translation - hips
    np.testing.assert_allclose(rel[:24], rel[24:48], atol=1e-12)
    assert np.ptp(rel[:, 0]) > 0.3  # and the leg swings
    # at t = 0 the left hip is at +25 degrees about Z
    assert np.degrees(quat_angle(m.objects["hip_l"].rotation[0], np.array([np.cos(np.radians(12.5)), 0, 0, np.sin(np.radians(12.5))]))) < 1e-9

    top = load_scene(SCENES / "spinning-top.yaml")
    shutter = 0.5 / 24  # 180 degrees at 24 fps
    m = evaluate(top, np.array([1.0 - shutter / 2, 1.0 + shutter / 2]))
    swept = np.degrees(quat_angle(m.objects["fin_a"].rotation[0], m.objects["fin_a"].rotation[1]))
    assert swept > 120  # one frame's shutter sweeps a large angle (150 degrees + precession)
