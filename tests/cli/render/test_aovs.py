"""AOVs in the EXR: depth, world normals and screen-space motion vectors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.frame_output import read_frame
from _support import run_motion

pytestmark = pytest.mark.render

# An orthographic camera 5 m in front of a wall (z = 0); a sphere slides along +x at
# 24 m/s: across the 1/48 s shutter it moves 0.5 m = 10 px at 80 px / 4 m.
SCENE = """
timeline: {fps: 24, first: 0, last: 1}
camera: {type: orthographic, position: [0, 0, -5], look_at: [0, 0, 0], ortho_width: 4}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: m, type: diffuse, color: 0.5}]
objects:
  - {name: wall, shape: rectangle, width: 10, height: 10, material: m, transform: {rotate: {euler: [0, 180, 0]}}}
  - name: ball
    shape: sphere
    radius: 0.5
    material: m
    transform: {translate: [0, 0, -1]}
    motion: {type: procedural, generators: [{type: ballistic, v0: [24, 0, 0], a: [0, 0, 0]}]}
render: {resolution: [80, 40], spp: 4, max_depth: 2}
output: {aovs: [depth, normal, motion], pixel_type: float}
"""


def test_depth_normal_and_motion_vectors(tmp_path: Path) -> None:
    scene = tmp_path / "aov.yaml"
    scene.write_text(SCENE)
    proc = run_motion("render", str(scene), "--frames", "0", "-o", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    frame = read_frame(tmp_path / "out" / "aov.0000.exr")
    assert set(frame.aovs) == {"Z", "N", "motion"}
    z, n, mv = frame.aovs["Z"], frame.aovs["N"], frame.aovs["motion"]
    assert z.shape == (40, 80) and n.shape == (40, 80, 3) and mv.shape == (40, 80, 2)
    corner = (slice(0, 3), slice(0, 3))  # the wall, far from the ball
    assert np.allclose(z[corner], 5.0, atol=1e-3)
    assert np.allclose(n[corner], [0, 0, -1], atol=1e-3)  # facing the camera
    assert np.allclose(mv[corner], 0.0, atol=1e-3)  # the wall does not move
    centre = (slice(18, 22), slice(38, 42))  # the ball's middle: always covered
    assert np.allclose(z[centre], 3.5, atol=0.05)  # sphere front at z = -1.5
    # +x in the world is image left (camera +X is left): the ball moves 10 px leftwards
    assert np.allclose(mv[centre][..., 0], -10.0, atol=0.2), mv[centre][..., 0]
    assert np.allclose(mv[centre][..., 1], 0.0, atol=0.2)
