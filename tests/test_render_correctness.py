"""Our motion_path integrator against Mitsuba's own `path` on static scenes: diffuse,
rough and smooth conductor, dielectric, plastic; area and environment lighting. Judged
against the noise floor: |ours - ref| must be no larger than |ref(seed a) - ref(seed b)|
allows. Objects are rendered both in the static set and as movers (rest-frame scenes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import activate, load

pytestmark = pytest.mark.render

SPP = 128


def _scene(tmp_path: Path, moving: bool) -> str:
    from motion.pipeline.frame_output import write_frame

    # a small lat-long environment: a bright band over a dim sky
    env = np.full((16, 32, 3), 0.2, np.float32)
    env[4:7] = [2.0, 1.6, 1.2]
    write_frame(tmp_path / "env.exr", env, pixel_type="float")
    # a tiny keyed motion that holds still: routes an object through the mover path
    motion = "motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: %s}, {time: 10, value: %s}]}}}" if moving else ""

    def obj(name: str, mat: str, x: float) -> str:
        pos = f"[{x}, 0.35, 0]"
        m = (motion % (pos, pos)) if moving else ""
        return f"  - {{name: {name}, shape: sphere, radius: 0.35, material: {mat}, transform: {{translate: {pos}}}, {m}}}\n".replace(", }", "}")

    return (
        """
timeline: {fps: 24, first: 0, last: 0}
camera: {position: [0, 1.2, 4], look_at: [0, 0.3, 0], fov: 45}
lights:
  - {type: envmap, file: env.exr, scale: 1.0}
materials:
  - {name: matte, type: diffuse, color: [0.7, 0.3, 0.2]}
  - {name: gold, type: conductor, preset: Au, roughness: 0.3}
  - {name: mirror, type: conductor, preset: none}
  - {name: glass, type: dielectric, ior: 1.5}
  - {name: coat, type: plastic, color: [0.1, 0.3, 0.7], roughness: 0.2}
  - {name: floor, type: diffuse, color: 0.5}
objects:
  - {name: floor, shape: rectangle, width: 8, height: 8, material: floor, transform: {rotate: {euler: [-90, 0, 0]}}}
  - {name: lamp, shape: rectangle, width: 1, height: 1, emission: {radiance: 6.0}, transform: {translate: [0, 2.5, 0], rotate: {euler: [90, 0, 0]}}}
"""
        + obj("a", "matte", -1.6)
        + obj("b", "gold", -0.8)
        + obj("c", "mirror", 0.0)
        + obj("d", "glass", 0.8)
        + obj("e", "coat", 1.6)
        + f"render: {{resolution: [64, 48], spp: {SPP}, max_depth: 6, rr_depth: 6, motion_blur: off}}\n"
    )


@pytest.mark.parametrize("moving", [False, True], ids=["static-set", "rest-frame-movers"])
def test_agrees_with_mitsuba_path(tmp_path: Path, moving: bool) -> None:
    activate()
    import mitsuba as mi

    from motion.pipeline.render.frame_renderer import FrameRenderer
    from motion.pipeline.render.inputs import evaluate_frames

    loaded = load(tmp_path, _scene(tmp_path, moving))
    (fi,) = evaluate_frames(loaded, [0])
    renderer = FrameRenderer(loaded)
    if moving:
        assert set(renderer.mover_names) == {"a", "b", "c", "d", "e"}
    ours = np.stack([renderer.render(fi)[0][..., :3] for _ in range(1)])[0]
    reference = renderer._full_scene(fi, None)  # the same records, Mitsuba's `path`
    ref_a = np.array(mi.render(reference, seed=11, spp=SPP))[..., :3]
    ref_b = np.array(mi.render(reference, seed=12, spp=SPP))[..., :3]
    assert np.isfinite(ours).all()
    floor = np.abs(ref_a - ref_b).mean()
    assert np.abs(ours - ref_a).mean() < 1.3 * floor, (np.abs(ours - ref_a).mean(), floor)
    assert ours.mean() == pytest.approx(ref_a.mean(), rel=0.02)
    # and it is a real picture, not two blank images agreeing
    assert ours.std() > 0.05
