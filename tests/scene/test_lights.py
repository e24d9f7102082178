"""The light records (pipeline/scene/lights.py): one key per light, and each record making
its own frame from its fields, read the same by the motion, bake and render stages."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion.pipeline.identity import Order
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


def test_a_second_environment_light_is_a_validation_error(tmp_path: Path) -> None:
    """Mitsuba takes one environment emitter a scene: a constant and an envmap (or two of
    either) validated fine and then failed every frame ("Only one environment emitter can
    be specified per scene", 3 attempts each). Now `validate` and `render` say which light,
    where, and what is expected, in one line each, exit 2, and the render makes nothing."""
    import subprocess

    from farm_util import MOTION

    from PIL import Image

    Image.new("RGB", (4, 2), (90, 120, 200)).save(tmp_path / "sky.png")
    scene = tmp_path / "two.yaml"
    scene.write_text("timeline: {fps: 24, first: 0, last: 1}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
                     "lights:\n  - {type: constant, radiance: 0.5}\n  - {type: point, position: [1, 3, 2], intensity: 30}\n"
                     "  - {name: sky, type: envmap, file: sky.png}\n  - {type: constant, radiance: 0.1}\n"
                     "objects: [{name: b, shape: sphere, radius: 0.5}]\nrender: {resolution: [16, 12], spp: 1}\n")
    expected = "expected at most one environment emitter (constant or envmap) in a scene, as Mitsuba allows one"
    for command in (["validate", str(scene)], ["render", str(scene), "-o", str(tmp_path / "out"), "--no-progress"]):
        res = subprocess.run([MOTION, *command], capture_output=True, text=True, timeout=120)
        assert res.returncode == 2, res.stderr
        assert "Traceback" not in res.stderr
        lines = [line for line in res.stderr.splitlines() if "environment" in line]
        assert lines == [f"{scene}:6:5: lights[2]: a second environment light (envmap; the first is lights[0], constant): {expected}",
                         f"{scene}:7:5: lights[3]: a second environment light (constant; the first is lights[0], constant): {expected}"], res.stderr
    assert not (tmp_path / "out").exists()
    one = scene.read_text().replace("  - {name: sky, type: envmap, file: sky.png}\n", "").replace("  - {type: constant, radiance: 0.1}\n", "")
    scene.write_text(one)
    assert subprocess.run([MOTION, "validate", str(scene)], capture_output=True, text=True, timeout=120).returncode == 0
