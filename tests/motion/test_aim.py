"""Aim at an object: `look_at: NAME` on the camera, a spot light or a projector tracks the
object's world origin at every sample time (keys, parents, simulation), so the subject
stays on the optical axis inside the shutter too; a typo gets a did-you-mean."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.dynamics import simulate
from motion.pipeline.errors import SceneError
from motion.pipeline.motion import evaluate
from motion.pipeline.motion.pose import quat_conj, quat_rotate
from motion.pipeline.scene import load_scene

SHOT = """
name: aim
timeline: {fps: 24, first: 0, last: 48}
render: {resolution: [32, 24], spp: 1}
camera:
  position: [0, 1.5, 6]
  look_at: %(aim)s
  motion:
    type: keyframes
    time_unit: seconds
    interpolation: catmull-rom
    channels:
      translate: {keys: [{time: 0, value: [0, 1.5, 6]}, {time: 1, value: [1.5, 1.0, 3]}, {time: 2, value: [-1, 2.0, 2]}]}
lights:
  - {type: constant, radiance: 0.5}
  - {type: spot, name: key, position: [3, 4, 3], look_at: %(aim)s, intensity: 20}
objects:
  - name: table
    shape: cube
    transform: {translate: [0, 0.5, 0], scale: [1, 0.5, 1]}
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        rotate: {keys: [{time: 0, euler: [0, 0, 0]}, {time: 2, euler: [0, 90, 0]}]}
  - name: crate
    shape: cube
    parent: table
    transform: {translate: [0.6, 1.4, 0.2], scale: 0.2}
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate: {keys: [{time: 0, value: [0.6, 1.4, 0.2]}, {time: 2, value: [-0.5, 1.4, -0.3]}]}
%(extra)s
"""


def _load(tmp_path: Path, aim: str = "crate", extra: str = ""):  # type: ignore[no-untyped-def]
    path = tmp_path / "aim.yaml"
    path.write_text(SHOT % {"aim": aim, "extra": extra})
    return load_scene(path)


def off_axis(pose, point: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Angle (rad) between each sample's local +Z and the direction to `point` [T, 3]."""
    local = quat_rotate(quat_conj(pose.rotation), point - pose.translation)
    return np.arctan2(np.linalg.norm(local[:, :2], axis=1), local[:, 2])


def test_a_dollying_camera_keeps_a_moving_object_at_the_image_centre(tmp_path: Path):
    """The camera dollies on catmull-rom keys; the crate slides on its table, which turns:
    at frame times and at sub-frame shutter samples the crate's world origin projects to
    the image centre (off the optical axis by < 1e-9 rad), as does the spot light's axis."""
    loaded = _load(tmp_path)
    times = np.array([0.0, 0.01, 0.5, 0.5 + 1 / 96, 1.0, 1.37, 1.9999, 2.0])
    motion = evaluate(loaded, times)
    crate = motion.objects["crate"].translation
    assert np.ptp(crate, axis=0).max() > 0.5  # it does move
    assert off_axis(motion.camera, crate).max() < 1e-9
    assert off_axis(motion.lights["key"], crate).max() < 1e-9
    # +Y of the camera stays in the plane of the view and its `up` (no roll)
    cam_up = quat_rotate(motion.camera.rotation, np.array([0.0, 1.0, 0.0]))
    cam_left = quat_rotate(motion.camera.rotation, np.array([1.0, 0.0, 0.0]))
    assert np.abs(cam_left[:, 1]).max() < 1e-12 and (cam_up[:, 1] > 0).all()


def test_the_aim_at_a_point_is_unchanged(tmp_path: Path):
    """A fixed `look_at` point still aims once (a keyed translate moves without re-aiming)."""
    motion = evaluate(_load(tmp_path, aim="[0, 1, 0]"), np.array([0.0, 1.0]))
    np.testing.assert_allclose(motion.camera.rotation[0], motion.camera.rotation[1], atol=0)


def test_an_aim_at_a_simulated_body_follows_the_simulation(tmp_path: Path):
    """A ball dropped under gravity: the camera's aim follows its simulated position."""
    extra = """  - name: ball
    shape: sphere
    radius: 0.1
    transform: {translate: [0, 3, 0]}
    motion: {type: dynamics, body: rigid, mass: 1}"""
    loaded = _load(tmp_path, aim="ball", extra=extra)
    sim = simulate(loaded, 1.0)
    times = np.array([0.0, 0.25, 0.5 + 1 / 96, 0.75])
    motion = evaluate(loaded, times, simulation=sim)
    ball = motion.objects["ball"].translation
    assert ball[0, 1] - ball[-1, 1] > 2.0  # it fell
    assert off_axis(motion.camera, ball).max() < 1e-9


def test_a_misspelt_aim_gets_did_you_mean(tmp_path: Path):
    with pytest.raises(SceneError, match=r"camera\.look_at: unknown object 'crat' \(look_at names an object\); did you mean 'crate'\?"):
        _load(tmp_path, aim="crat")


def test_an_aimed_camera_with_a_keyed_rotation_is_refused(tmp_path: Path):
    text = SHOT % {"aim": "crate", "extra": ""}
    text = text.replace("      translate: {keys: [{time: 0, value: [0, 1.5, 6]}", "      rotate: {keys: [{time: 0, euler: [0, 0, 0]}]}\n      translate: {keys: [{time: 0, value: [0, 1.5, 6]}", 1)
    path = tmp_path / "rot.yaml"
    path.write_text(text)
    with pytest.raises(SceneError, match=r"camera\.motion: look_at aims at 'crate', which sets the rotation; a keyed rotate channel"):
        load_scene(path)


def test_a_light_aimed_at_a_moving_object_is_posed_per_frame_by_the_renderer(tmp_path: Path):
    """The spot light has no motion of its own, but its aim moves: the renderer poses it
    per path (a moving light), not once in the static set."""
    from motion.pipeline.render.translate.roles import sort_scene

    roles = sort_scene(_load(tmp_path))
    assert [light.name for _, light in roles.moving_lights] == ["key"]
    assert not sort_scene(_load(tmp_path, aim="[0, 1, 0]")).moving_lights
