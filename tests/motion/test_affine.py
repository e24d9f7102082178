"""Affine hierarchies: parent frames compose as 4x4 matrices, so a non-uniform parent scale
over a rotated child is exact (world_from_object = T R S, S the symmetric stretch of the
polar decomposition), mirrors included; the stretch survives a bake file and the
renderer's rest frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from motion.pipeline.motion import Pose, evaluate
from motion.pipeline.motion.pose import UnrepresentablePoseError, compose, matrix_to_quat, polar_stretch, quat_to_matrix
from motion.pipeline.scene import load_scene

RNG = np.random.default_rng(47)
FPS = 24


def random_pose(count: int, uniform: bool = False) -> Pose:
    q = Rotation.random(count, random_state=RNG).as_quat(scalar_first=True)
    s = RNG.uniform(0.3, 3.0, (count, 1 if uniform else 3)).repeat(3 if uniform else 1, axis=1)
    return Pose(RNG.normal(size=(count, 3)), q, s)


def test_a_chain_of_non_uniform_scales_and_rotations_is_the_product_of_its_matrices():
    """Three levels of random non-uniform scales under random rotations: the composed
    pose's matrix is the product of the 4x4 matrices (1e-12), its stretch symmetric
    positive definite; the per-axis product of scales misses by O(1)."""
    a, b, c = random_pose(64), random_pose(64), random_pose(64)
    ab = compose(a, b)
    abc = compose(ab, c)
    expected = a.matrices() @ b.matrices() @ c.matrices()
    np.testing.assert_allclose(abc.matrices(), expected, atol=1e-12 * np.abs(expected).max())
    s = abc.stretch()
    np.testing.assert_array_equal(s, np.swapaxes(s, 1, 2))
    assert np.linalg.eigvalsh(s).min() > 0
    points = RNG.normal(size=(5, 3))
    np.testing.assert_allclose(abc.transform_points(points), np.einsum("tij,vj->tvi", expected[:, :3, :3], points) + expected[:, None, :3, 3], atol=1e-11)
    per_axis = Pose(ab.translation, ab.rotation, ab.scale)  # the off-diagonal terms dropped
    assert np.abs(per_axis.matrices() - a.matrices() @ b.matrices()).max() > 0.1


def test_a_uniform_parent_scale_keeps_the_per_axis_product_bit_for_bit():
    """Where the parent's scale is uniform the result is the old formula, bit for bit, and
    carries no off-diagonal terms (so scenes without non-uniform parents bake the same)."""
    p, c = random_pose(32, uniform=True), random_pose(32)
    out = compose(p, c)
    assert out.stretch_offdiag is None
    np.testing.assert_array_equal(out.scale, p.scale * c.scale)


def test_polar_stretch_is_scipys_polar_decomposition():
    m = np.einsum("kij,kjl->kil", Rotation.random(20, random_state=RNG).as_matrix(), RNG.normal(size=(20, 3, 3)))
    m[np.linalg.det(m) < 0] *= -1.0  # det > 0: a rotation times a positive stretch
    u, p = polar_stretch(m)
    for k in range(len(m)):
        su, sp = scipy.linalg.polar(m[k], side="right")
        np.testing.assert_allclose(u[k], su, atol=1e-12)
        np.testing.assert_allclose(p[k], sp, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(u)), u, atol=1e-14)


def test_mirrors_and_collapses_under_a_non_uniform_scale_are_held_exactly():
    """Any 3x3 is a rotation times a symmetric matrix: a parent scale (-1, 2, 1) or
    (0, 2, 1) over a turned child with a non-uniform scale of its own composes to the
    exact product, the rotation a proper one, the mirror one negative eigenvalue of the
    stretch (as a negative `scale` is); only a non-finite product is refused."""
    p = Pose(np.zeros((3, 3)), np.tile([1.0, 0, 0, 0], (3, 1)), np.array([[1.0, 2.0, 1.0], [-1.0, 2.0, 1.0], [0.0, 2.0, 1.0]]))
    turn = Rotation.from_euler("zx", [30, 50], degrees=True)
    c = Pose(np.tile([0.1, 0.2, 0.3], (3, 1)), np.tile(turn.as_quat(scalar_first=True), (3, 1)), np.array([[1.0, 3.0, 0.5]] * 3))
    out = compose(p, c)
    np.testing.assert_allclose(out.matrices(), p.matrices() @ c.matrices(), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(quat_to_matrix(out.rotation)), 1.0, atol=1e-14)
    eig = np.linalg.eigvalsh(out.stretch())
    assert (eig[0] > 0).all() and eig[1][0] < 0 < eig[1][1] and abs(eig[2][0]) < 1e-14
    bad = p._replace(scale=np.array([[1.0, 2.0, 1.0], [np.inf, 2.0, 1.0], [1.0, 2.0, 1.0]]))
    with pytest.raises(UnrepresentablePoseError, match="not finite") as exc, np.errstate(invalid="ignore"):
        compose(bad, c)
    assert list(exc.value.samples) == [1]


HIERARCHY = """
name: box
timeline: {fps: 24, first: 0, last: 90}
camera: {position: [0, 2, 8], look_at: [0, 2, 0]}
lights:
  - {type: constant, radiance: 0.3}
objects:
  - name: root
    shape: empty
    transform: {scale: [1, 2, 1]}
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate: {keys: [{time: 0, value: [0, 0, 0]}, {time: 1.25, value: [0, 2.52, 0]}, {time: 2.5, value: [0, 2.52, 0]}, {time: 3.708329916, value: [0, 0, 0]}]}
  - name: inner
    shape: cube
    parent: root
    transform: {scale: [0.67008, 1, 0.67008]}
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        rotate: {keys: [{time: 1.25, quaternion: [1, 0, 0, 0]}, {time: 2.5, quaternion: [0, 1, 0, 0]}]}
  - name: grandchild
    shape: sphere
    parent: inner
    transform: {translate: [0, 1, 0], rotate: {axis: [0, 0, 1], angle: 30}, scale: [1, 0.5, 2]}
"""


def test_the_box_animated_hierarchy_in_scene_yaml_matches_the_4x4_product(tmp_path: Path):
    """BoxAnimated's hierarchy written directly in YAML (a cube of half extents
    (0.33504, 0.5, 0.33504) under a root scaled [1, 2, 1]): at frame 45 the box spans
    y 1.85-3.19 and z -0.5..0.5, like the glTF import (tests/scene/imports/test_gltf.py), and a
    grandchild under it is the product of the three matrices."""
    path = tmp_path / "box.yaml"
    path.write_text(HIERARCHY)
    motion = evaluate(load_scene(path), np.array([1.0, 45 / FPS, 2.2]))
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])  # the unit cube
    at45 = motion.objects["inner"].transform_points(corners)[1]
    np.testing.assert_allclose([at45[:, 1].min(), at45[:, 1].max()], [2.52 - 0.67008, 2.52 + 0.67008], atol=1e-9)
    np.testing.assert_allclose([at45[:, 2].min(), at45[:, 2].max()], [-0.5, 0.5], atol=1e-9)
    root, inner, grand = (motion.objects[n] for n in ("root", "inner", "grandchild"))
    local_inner = np.diag([0.67008, 1.0, 0.67008, 1.0])
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_euler("x", 90.0, degrees=True).as_matrix()  # halfway from 0 to 180 degrees
    np.testing.assert_allclose(inner.matrices()[1], root.matrices()[1] @ turn @ local_inner, atol=1e-12)
    local_grand = np.eye(4)
    local_grand[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix() @ np.diag([1, 0.5, 2])
    local_grand[:3, 3] = (0, 1, 0)
    np.testing.assert_allclose(grand.matrices(), inner.matrices() @ local_grand, atol=1e-12)


def test_a_composed_mirror_in_scene_yaml_is_the_4x4_product(tmp_path: Path):
    """A rotated child whose own scale turns negative (a procedural channel) under the
    stretched, turning box: the grandchild's world matrix is still the product of the
    three matrices (before, a mirror under a non-uniform scale had no exact form)."""
    text = HIERARCHY.replace("rotate: {axis: [0, 0, 1], angle: 30}, scale: [1, 0.5, 2]}", "rotate: {axis: [0, 0, 1], angle: 30}, scale: [1, 0.5, 2]}\n    motion:\n      type: procedural\n      channels: {scale: ['-1', '1', '1']}")
    path = tmp_path / "mirror.yaml"
    path.write_text(text)
    motion = evaluate(load_scene(path), np.array([0.0, 45 / FPS, 2.2]))
    local_grand = np.eye(4)
    local_grand[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix() @ np.diag([-1, 0.5, 2])
    local_grand[:3, 3] = (0, 1, 0)
    grand = motion.objects["grandchild"]
    np.testing.assert_allclose(grand.matrices(), motion.objects["inner"].matrices() @ local_grand, atol=1e-12)
    assert (np.linalg.det(grand.stretch()) < 0).all()


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_the_stretch_survives_a_bake_file_and_old_files_read_as_diagonal(tmp_path: Path, suffix: str):
    """Frames 0-1 hold the inner box unrotated (diagonal stretch), frames 44-46 turned
    under the stretched root: the file carries `stretch` where a pose has it, the frames
    read back give the same matrices, and a file without the key (written before
    stretches) reads as diagonal."""
    from motion.pipeline.bake import bake, read_baked, write_baked

    path = tmp_path / "box.yaml"
    path.write_text(HIERARCHY)
    loaded = load_scene(path)
    baked = bake(loaded, [0, 1, 44, 45, 46])
    out = write_baked(baked, tmp_path / f"m{suffix}")
    back = read_baked(out)
    for f0, f1 in zip(baked.frames, back.frames):
        for m0, m1 in ((f0.at_frame, f1.at_frame), (f0.across_shutter, f1.across_shutter)):
            for name in ("root", "inner", "grandchild"):
                np.testing.assert_allclose(m1.objects[name].matrices(), m0.objects[name].matrices(), atol=1e-12)
    assert back.frames[0].at_frame.objects["inner"].stretch_offdiag is None
    assert back.frames[3].at_frame.objects["grandchild"].stretch_offdiag is not None
    # an old file: no stretch keys at all
    if suffix == ".json":
        import json

        doc = json.loads(out.read_text())
        for fr in doc["frames"]:
            for part in ("at_frame", "samples"):
                for pose in fr[part]["objects"].values():
                    pose.pop("stretch", None)
        out.write_text(json.dumps(doc))
        old = read_baked(out)
        assert all(p.stretch_offdiag is None for f in old.frames for p in f.at_frame.objects.values())


TWIN = """
name: %(name)s
timeline: {fps: 24, first: 0, last: 0}
camera: {position: [0.2, 0.5, 3.5], look_at: [0.2, 0.4, 0], fov: 40}
lights:
  - {type: constant, radiance: 0.4}
  - {type: directional, direction: [-0.4, -1, -0.6], irradiance: 3}
render: {resolution: [48, 36], spp: 4, motion_blur: off}
objects:
%(objects)s
"""
MOVING = """
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate: {keys: [{time: 0, value: [0, 0.3, 0]}, {time: 1, value: [0.5, 0.3, 0]}]}"""


def _cube_obj(path: Path, m: np.ndarray) -> None:
    """The unit cube's 12 triangles (the scene's `cube`: [-0.5, 0.5]^3), its corners mapped
    by m; no vertex shared between faces, so its normals are the faces' (flat, as the cube's)."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    world = (m @ np.c_[corners, np.ones(8)].T).T[:, :3]
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]  # outward, counter-clockwise
    lines = []
    for k, quad in enumerate(quads):
        lines += [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in world[quad]]
        lines += [f"f {4 * k + 1} {4 * k + 2} {4 * k + 3}", f"f {4 * k + 1} {4 * k + 3} {4 * k + 4}"]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.slow  # two renders each
@pytest.mark.parametrize("moving", [False, True], ids=["static", "mover"])
def test_a_rotated_child_under_a_non_uniform_scale_renders_as_its_sheared_twin(tmp_path: Path, moving: bool):
    """A cube turned about X and Z under a parent scaled [1, 2, 1] renders like a mesh of
    the cube's corners mapped by the closed-form 4x4 product (the renderer applies the full
    stretch in the rest frame: the static set and a mover alike)."""
    from _support import run_motion
    from motion.pipeline.frame_output import read_frame

    turn = Rotation.from_euler("xz", [40, 30], degrees=True)
    stretch = np.diag([1.0, 2.0, 1.0, 1.0])
    child = np.eye(4)
    child[:3, :3] = turn.as_matrix() @ np.diag([0.5, 0.4, 0.3])
    lift = np.eye(4)
    lift[:3, 3] = (0, 0.3, 0)  # the parent's translate: in the mesh, or keyed on the moving twin
    _cube_obj(tmp_path / "twin.obj", stretch @ child if moving else lift @ stretch @ child)
    w, x, y, z = (float(v) for v in turn.as_quat(scalar_first=True))
    hierarchy = (f"  - name: stretch\n    shape: empty\n    transform: {{translate: [0, 0.3, 0], scale: [1, 2, 1]}}{MOVING if moving else ''}\n"
                 f"  - name: box\n    shape: cube\n    parent: stretch\n    transform: {{rotate: {{quaternion: [{w!r}, {x!r}, {y!r}, {z!r}]}}, scale: [0.5, 0.4, 0.3]}}\n")
    twin = f"  - name: box\n    shape: mesh\n    file: twin.obj\n" + (f"    transform: {{translate: [0, 0.3, 0]}}{MOVING}\n" if moving else "")
    images = []
    for name, objects in (("tree", hierarchy), ("twin", twin)):
        (tmp_path / f"{name}.yaml").write_text(TWIN % {"name": name, "objects": objects})
        proc = run_motion("render", str(tmp_path / f"{name}.yaml"), "-o", str(tmp_path / name))
        assert proc.returncode == 0, proc.stderr
        images.append(read_frame(next((tmp_path / name).glob(f"{name}.*.exr"))).rgba[..., :3])
    tree, ours = images
    covered = (np.abs(ours - 0.4).max(axis=-1) > 0.02).mean()
    assert covered > 0.05  # the box fills part of the frame
    assert np.abs(tree - ours).mean() < 2e-3, np.abs(tree - ours).mean()
