"""Non-rigid geometry: particle systems (spheres in the one traversal) and skinned meshes (movers of the same traversal on their fitted rigid tracks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import load, render
from _scenes import ARM_BONES, FOUNTAIN, orange_pixels

pytestmark = pytest.mark.render

def test_particle_system_renders_and_grows(tmp_path: Path) -> None:
    (early, late), stats, renderer = render(load(tmp_path, FOUNTAIN), [2, 10])
    # particles are neither time slices nor rigid movers: spheres in the one traversal
    assert renderer.particle_names == ("fountain",) and not renderer.slice_names and not renderer.mover_names
    assert 0 < orange_pixels(early) < orange_pixels(late)  # more particles, higher up, later
    assert stats[1].kernels_compiled == 0


SKINNED = """
timeline: {fps: 24, first: 0, last: 24}
camera: {type: orthographic, position: [0, 1, -6], look_at: [0, 1, 0], ortho_width: 4}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: arm, type: diffuse, color: [0.9, 0.2, 0.2]}]
objects:
  - name: arm
    shape: cube
    size: [0.3, 2.0, 0.3]
    material: arm
    transform: {translate: [0, 1, 0]}
    deform:
      type: skinning
      auto: true
""" + ARM_BONES + """\
render: {resolution: [64, 64], spp: 4, max_depth: 2, shutter_samples: 3, motion_blur: off}
"""


def test_skinned_mesh_bends(tmp_path: Path) -> None:
    (straight, bent), _, renderer = render(load(tmp_path, SKINNED), [0, 24])
    assert renderer.deforming_names == ("arm",) and not renderer.slice_names  # in the traversal
    red = lambda img: (img[..., 0] > img[..., 1] + 0.3)  # noqa: E731
    s, b = red(straight), red(bent)
    assert s.sum() > 50 and b.sum() > 50
    rows_s, rows_b = np.where(s.any(axis=1))[0], np.where(b.any(axis=1))[0]
    # bent 90 degrees at the middle: the top half now points sideways, so the arm covers
    # fewer rows and reaches further across
    assert len(rows_b) < 0.8 * len(rows_s)
    assert np.where(b.any(axis=0))[0].size > 1.5 * np.where(s.any(axis=0))[0].size


def test_a_skinned_primitive_renders_at_its_own_tessellation(tmp_path: Path) -> None:
    """`detail` sets how finely a skinned primitive is tessellated for the motion stage; the
    renderer's slices built the primitive at the default 16 whatever it said, and a scene
    with another detail failed with an IndexError on its first frame."""
    text = SKINNED.replace("      auto: true\n", "      auto: true\n      detail: 4\n")
    assert "detail: 4" in text
    (img,), _, _ = render(load(tmp_path, text), [24])
    assert (img[..., 0] > img[..., 1] + 0.3).sum() > 50
