"""Non-rigid geometry: particle systems (spheres in the one traversal) and skinned meshes (movers of the same traversal on their fitted rigid tracks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import load, render
from _scenes import FOUNTAIN, SKINNED_ARM, orange_pixels

pytestmark = pytest.mark.render

def test_particle_system_renders_and_grows(tmp_path: Path) -> None:
    (early, late), stats, renderer = render(load(tmp_path, FOUNTAIN), [2, 10])
    # particles are neither time slices nor rigid movers: spheres in the one traversal
    assert renderer.particle_names == ("fountain",) and not renderer.deforming_names and not renderer.mover_names
    assert 0 < orange_pixels(early) < orange_pixels(late)  # more particles, higher up, later
    assert stats[1].kernels_compiled == 0


SKINNED = """
timeline: {fps: 24, first: 0, last: 24}
camera: {type: orthographic, position: [0, 1, -6], look_at: [0, 1, 0], ortho_width: 4}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: arm, type: diffuse, color: [0.9, 0.2, 0.2]}]
objects:
""" + SKINNED_ARM + """\
render: {resolution: [64, 64], spp: 4, max_depth: 2, shutter_samples: 3, motion_blur: off}
"""


def test_skinned_mesh_bends(tmp_path: Path) -> None:
    (straight, bent), _, renderer = render(load(tmp_path, SKINNED), [0, 24])
    assert renderer.deforming_names == ("arm",)  # in the traversal
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


FLOCK = """
timeline: {fps: 24, first: 0, last: 4}
camera: {position: [0, 2, 8], look_at: [0, 1.5, 0], fov: 50, shutter: {angle: 180}}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: dart, type: diffuse, color: [0.9, 0.2, 0.1]}]
objects:
  - name: darts
    shape: cube
    size: [0.3, 0.2, 0.6]
    material: dart
    deform: {type: flock, count: 24, seed: 3, spawn_center: [-1, 1.5, 0], spawn_size: [1, 0.5, 1], speed: 2, goal: [2, 1.5, 0],
             bounds: {min: [-4, 0.5, -2], max: [4, 3, 2]}}
render: {resolution: [64, 48], spp: 4, max_depth: 2}
"""


def test_a_flock_is_one_mover_per_agent_sharing_one_template(tmp_path: Path) -> None:
    """A flock's agents are instances of one agent mesh, each with its own rigid motion
    (fitted to the agent mesh: exact, agents are rigid copies of it): 24 movers of the one
    traversal, one template in the atlas, no recompilation on a warm frame. Before, the
    flock was one flattened mesh drawn as `time_slices` frozen copies."""
    (first, later), stats, renderer = render(load(tmp_path, FLOCK), [1, 4])
    cache = renderer.cache
    assert renderer.deforming_names == ("darts",) and cache.deforming.movers == 24
    assert cache.integrator.world.rigid == 24 and len(cache.atlas.keys) == 1
    (g,) = cache.deforming.meshes
    # every agent's fitted track puts the agent mesh on the agent's baked vertices
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.motion.pose import quat_rotate
    from motion.pipeline.render.poses.stacked import stack_frame

    fi = stack_frame(evaluate_frames(load(tmp_path, FLOCK, "again.yaml"), [4])[0])
    cache.deforming.fit(fi)
    t, q, s = fi.objects["darts"]
    world = quat_rotate(q[:, None], fi.vertices["darts"] * s[:, None, :]) + t[:, None]  # [1+N, 24 x V, 3]
    tt, qq = g.track
    posed = quat_rotate(qq[:, :, None], g.rest[None, None]) + tt[:, :, None]  # [24, 1+N, V, 3]
    np.testing.assert_allclose(np.swapaxes(posed, 0, 1).reshape(world.shape), world, atol=1e-9)
    red = lambda img: (img[..., 0] > img[..., 1] + 0.3).sum()  # noqa: E731
    assert red(first) > 20 and red(later) > 20
    assert stats[1].kernels_compiled == 0


def test_a_deforming_mesh_that_outgrows_its_atlas_cell_renders_as_a_cold_frame(tmp_path: Path) -> None:
    """A blend shape growing 8x between frames 0 and 4: its templates outgrow the atlas
    cell laid out on the cold frame (three times the size then), so the warm frame lays the
    atlas out again (`SceneCache._draw_deforming`) and draws what a fresh renderer draws
    on frame 4 as its cold frame."""
    verts = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.0, 0.3]])
    (tmp_path / "tet.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in verts) + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    keys = f"[{{time: 0, vertices: {verts.tolist()}}}, {{time: 4, vertices: {(verts * 8).tolist()}}}]"
    text = f"""
timeline: {{fps: 24, first: 0, last: 4}}
camera: {{position: [1.2, 1.2, 6], look_at: [1.2, 1.2, 0], fov: 50}}
lights: [{{type: constant, radiance: 1.0}}]
materials: [{{name: red, type: diffuse, color: [0.9, 0.2, 0.1]}}]
objects:
  - {{name: tet, shape: mesh, file: tet.obj, material: red, deform: {{type: blend-shapes, keys: {keys}}}}}
render: {{resolution: [48, 32], spp: 8, max_depth: 2}}
"""
    loaded = load(tmp_path, text)
    (first,), _, renderer = render(loaded, [0])
    cell = renderer.cache.atlas.layout.cell
    (warm,), stats, _ = render(loaded, [4], renderer=renderer)
    assert not stats[0].cold and renderer.cache.atlas.layout.cell > 3 * cell  # laid out again
    (cold,), _, _ = render(load(tmp_path, text, "again.yaml"), [4])
    red = lambda img: (img[..., 0] > img[..., 1] + 0.3).sum()  # noqa: E731
    assert red(warm) > 4 * red(first) > 0
    np.testing.assert_allclose(warm, cold, atol=1e-5)
