"""Deformation: skinning weights, rest pose, a 90-degree bend; blend shapes and their checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.errors import SceneError
from motion.pipeline.motion import evaluate
from motion.pipeline.motion.deform import bind_mesh, bone_poses, normalise_weights, skin_weights
from motion.pipeline.scene import load_scene

from _scenes import ARM_BONES

ARM = """
camera: {position: [0, 0, 5], look_at: [0, 0, 0]}
objects:
  - name: arm
    shape: cylinder
    radius: 0.1
    height: 2
    deform:
      type: skinning
      %s
      detail: 8
""" + ARM_BONES


def _load(tmp_path: Path, text: str):  # type: ignore[no-untyped-def]
    path = tmp_path / "s.yaml"
    path.write_text(text)
    return load_scene(path)


def test_auto_weights_sum_to_one_with_at_most_four_influences(tmp_path: Path) -> None:
    loaded = _load(tmp_path, ARM % "auto: true")
    skin = loaded.scene.objects[0].deform
    verts, _ = bind_mesh(loaded, loaded.scene.objects[0], skin.detail)
    _, _, bind = bone_poses(loaded, ("objects", 0, "deform"), skin, np.zeros(1))
    idx, w = skin_weights(loaded, ("objects", 0, "deform"), skin, verts, bind)
    assert idx.shape[1] <= 4
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    # the far ends belong to their own bone
    assert np.all(idx[verts[:, 1] < -0.9, 0] == 0) and np.all(idx[verts[:, 1] > 0.9, 0] == 1)
    idx, w = normalise_weights(np.array([[5.0, 1, 1, 1, 2, 0]]))
    assert idx.tolist() == [[0, 4, 1, 2]]  # the 4 largest, ties in bone order; the 5th influence dropped
    np.testing.assert_allclose(w, [[5 / 9, 2 / 9, 1 / 9, 1 / 9]])


def test_rest_pose_reproduces_the_bind_mesh(tmp_path: Path) -> None:
    loaded = _load(tmp_path, ARM % "auto: true")
    m = evaluate(loaded, np.array([0.0]))
    verts, _ = bind_mesh(loaded, loaded.scene.objects[0], 8)
    np.testing.assert_allclose(m.vertices["arm"][0], verts, atol=1e-14)


def test_90_degree_bend_moves_only_weighted_vertices(tmp_path: Path) -> None:
    probe = _load(tmp_path, ARM % "auto: true")
    verts, _ = bind_mesh(probe, probe.scene.objects[0], 8)
    # explicit weights: the lower half on `upper`, the upper half on `lower`, a blend at y = 0
    rows = []
    for y in verts[:, 1]:
        rows.append("{upper: 1}" if y < -1e-9 else "{lower: 1}" if y > 1e-9 else "{upper: 1, lower: 1}")
    loaded = _load(tmp_path, ARM % ("weights: [" + ", ".join(rows) + "]"))
    m = evaluate(loaded, np.array([0.0, 1.0]))
    bent = m.vertices["arm"][1]
    lower = verts[:, 1] < -1e-9
    upper = verts[:, 1] > 1e-9
    np.testing.assert_array_equal(bent[lower], verts[lower])  # unweighted by `lower`: untouched
    # weighted vertices turn 90 degrees about +Z through the joint at the origin: (x, y) -> (-y, x)
    np.testing.assert_allclose(bent[upper][:, 0], -verts[upper][:, 1], atol=1e-12)
    np.testing.assert_allclose(bent[upper][:, 1], verts[upper][:, 0], atol=1e-12)
    # the seam is the average of both bones: halfway between unbent and bent
    seam = ~(lower | upper)
    expect = 0.5 * (verts[seam] + np.column_stack((-verts[seam][:, 1], verts[seam][:, 0], verts[seam][:, 2])))
    np.testing.assert_allclose(bent[seam], expect, atol=1e-12)


def test_weight_rows_must_match_the_mesh(tmp_path: Path) -> None:
    loaded = _load(tmp_path, ARM % "weights: [{upper: 1}, {lower: 1}]")
    with pytest.raises(SceneError, match=r"objects\[0\]\.deform\.weights.*2 weight rows for a bind mesh of 155"):
        evaluate(loaded, np.zeros(1))


BLEND = """
camera: {position: [0, 0, 5], look_at: [0, 0, 0]}
objects:
  - name: flag
    shape: mesh
    file: flag.obj
    deform:
      type: blend-shapes
      interpolation: %s
      time_unit: seconds
      keys:
        - {time: 0, file: flag.obj}
        - {time: 1, vertices: [[0, 0, 1], [1, 0, 1], [0, 1, 1]]}
        - {time: 2, vertices: [[0, 0, 0], [1, 0, 0], [0, 1, 2]]}
"""


def test_blend_shapes_per_vertex(tmp_path: Path) -> None:
    (tmp_path / "flag.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    m = evaluate(_load(tmp_path, BLEND % "linear"), np.array([0.5, 1.5, 3.0]))
    v = m.vertices["flag"]
    np.testing.assert_allclose(v[0], [[0, 0, 0.5], [1, 0, 0.5], [0, 1, 0.5]])
    np.testing.assert_allclose(v[1][:, 2], [0.5, 0.5, 1.5])
    np.testing.assert_allclose(v[2][:, 2], [0, 0, 2])  # held after the last key
    hold = evaluate(_load(tmp_path, BLEND % "hold"), np.array([0.99]))
    np.testing.assert_allclose(hold.vertices["flag"][0][:, 2], 0.0)
    cr = evaluate(_load(tmp_path, BLEND % "catmull-rom"), np.array([1.0, 0.5]))
    np.testing.assert_allclose(cr.vertices["flag"][0][:, 2], 1.0)  # passes through the key


def test_blend_shape_vertex_counts_are_checked(tmp_path: Path) -> None:
    (tmp_path / "flag.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    text = (BLEND % "linear").replace("[[0, 0, 0], [1, 0, 0], [0, 1, 2]]", "[[0, 0, 0], [1, 0, 0]]")
    with pytest.raises(SceneError, match=r"objects\[0\]\.deform\.keys\[2\]: key mesh has 2 vertices; expected 3"):
        evaluate(_load(tmp_path, text), np.zeros(1))
