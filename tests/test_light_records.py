"""The light records (pipeline/scene/lights.py): one key per light, and each record making
its own frame from its fields, read the same by the motion, bake and render stages."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion.pipeline.bake.fingerprint import Order
from motion.pipeline.motion.evaluate import evaluate
from motion.pipeline.motion.pose import quat_rotate
from motion.pipeline.scene import load_scene
from motion.pipeline.scene.lights import LIGHT_TYPES, light_key
from motion.pipeline.scene.schema import LIGHT_TYPES as SCHEMA_LIGHT_TYPES

SCENE = """
timeline: {fps: 24, first: 0, last: 0}
camera: {position: [0, 5, 5], look_at: [0, 0, 0], fov: 50}
lights:
  - {type: spot, position: [0, 3, 0], look_at: [0, 0, 0], intensity: 20, parent: rig}
  - {type: directional, name: sun, direction: [0, 0, -2], irradiance: 1.0}
  - {type: point, position: [1, 2, 3], intensity: 5, parent: rig}
  - {type: constant, radiance: 0.1}
materials:
  - {name: floor, type: diffuse, color: 0.5}
objects:
  - {name: rig, shape: empty, transform: {translate: [1, 0, 0], scale: [2, 2, 2]}}
  - {name: floor, shape: rectangle, width: 8, height: 8, material: floor}
"""


def test_one_light_key_for_motion_and_bake(tmp_path: Path) -> None:
    """Unnamed lights are `light<index>` in the evaluated motion and the bake's order alike,
    from the one function the schema re-exports with the registry."""
    path = tmp_path / "lights.yaml"
    path.write_text(SCENE)
    loaded = load_scene(path, assets=False)
    keys = [light_key(light, i) for i, light in enumerate(loaded.scene.lights)]
    assert keys == ["light0", "sun", "light2", "light3"]
    assert list(evaluate(loaded, np.array([0.0])).lights) == keys
    assert list(Order.of(loaded.scene).lights) == keys
    assert SCHEMA_LIGHT_TYPES is LIGHT_TYPES


def test_each_record_makes_its_own_frame(tmp_path: Path) -> None:
    """A spot aimed straight down (the vertical-aim case) points its +Z down, a directional
    light its +Z along its direction, a point light sits at its position in its scaled parent;
    only the lights placed by a point or a direction keep a rigid frame."""
    path = tmp_path / "lights.yaml"
    path.write_text(SCENE)
    loaded = load_scene(path, assets=False)
    poses = evaluate(loaded, np.array([0.0])).lights
    z = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(quat_rotate(poses["light0"].rotation[0], z), [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(quat_rotate(poses["sun"].rotation[0], z), [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(poses["light2"].translation[0], [3.0, 4.0, 6.0])
    assert {name for name, record in LIGHT_TYPES.items() if record.rigid_frame} == {"point", "spot", "directional", "projector"}
