"""Inverse kinematics (pipeline/motion/ik.py): the two-bone solver is exact for reachable
targets and finite for unreachable ones, CCD respects joint limits, the weight blends with
the keyed pose, and on the stairs example the planted feet do not slide or sink."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from _support import SCENES
from motion.pipeline.errors import SceneError
from motion.pipeline.motion import evaluate
from motion.pipeline.motion.ik import chain_world, solve_ccd, solve_two_bone
from motion.pipeline.motion.pose import Pose, quat_conj, quat_mul, quat_normalize, quat_rotate
from motion.pipeline.scene import load_scene
from motion.pipeline.scene.motion_schema import JointLimit


def random_quats(rng: np.random.Generator, n: int) -> np.ndarray:
    return quat_normalize(rng.normal(size=(n, 4)))


def pose(t: np.ndarray, q: np.ndarray) -> Pose:
    return Pose(t, q, np.ones_like(t))


def two_bone_chain(rng: np.random.Generator, n: int) -> tuple[Pose, list[Pose], np.ndarray, np.ndarray]:
    """A random base pose and a hip-knee-ankle chain with random bone lengths and keyed
    rotations; returns (base, locals, l1, l2)."""
    base = pose(rng.normal(size=(n, 3)), random_quats(rng, n))
    l1 = rng.uniform(0.2, 1.0, n)
    l2 = rng.uniform(0.2, 1.0, n)
    locals_ = [
        pose(np.zeros((n, 3)), random_quats(rng, n)),
        pose(np.stack((np.zeros(n), -l1, np.zeros(n)), axis=1), random_quats(rng, n)),
        pose(np.stack((np.zeros(n), -l2, np.zeros(n)), axis=1), random_quats(rng, n)),
    ]
    return base, locals_, l1, l2


def solved_chain(base: Pose, locals_: list[Pose], rotations: list[np.ndarray]) -> list[Pose]:
    new = [Pose(p.translation, q, p.scale) for p, q in zip(locals_, rotations)] + locals_[len(rotations):]
    return chain_world(base, new)


def test_two_bone_reaches_every_reachable_target_exactly() -> None:
    rng = np.random.default_rng(0)
    n = 2000
    base, locals_, l1, l2 = two_bone_chain(rng, n)
    root = chain_world(base, locals_)[0].translation
    # targets at distances spanning the whole reachable shell, in random directions
    d = np.abs(l1 - l2) + rng.uniform(1e-6, 1 - 1e-6, n) * (l1 + l2 - np.abs(l1 - l2))
    u = rng.normal(size=(n, 3))
    target = root + d[:, None] * u / np.linalg.norm(u, axis=1, keepdims=True)
    pole = root + rng.normal(size=(n, 3))
    world = solved_chain(base, locals_, solve_two_bone(base, locals_, target, pole))
    np.testing.assert_allclose(world[2].translation, target, atol=1e-9)
    # bones keep their lengths; the knee bends towards the pole
    np.testing.assert_allclose(np.linalg.norm(world[1].translation - world[0].translation, axis=1), l1, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(world[2].translation - world[1].translation, axis=1), l2, atol=1e-12)
    axis = (target - root) / d[:, None]
    side = lambda p: (p - root) - np.einsum("ij,ij->i", p - root, axis)[:, None] * axis  # noqa: E731
    bend = np.einsum("ij,ij->i", side(world[1].translation), side(pole))
    assert (bend >= -1e-9).all()


def test_two_bone_keeps_the_knee_a_hinge() -> None:
    # the middle joint turns about the bend-plane normal only: the knee's keyed hinge axis
    # (local Z here, the legs bend in the XY plane) stays normal to the leg's plane
    rng = np.random.default_rng(1)
    n = 500
    base = pose(np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1)))
    bend = np.radians(rng.uniform(5, 60, n))
    knee_q = np.stack((np.cos(bend / 2), np.zeros(n), np.zeros(n), np.sin(bend / 2)), axis=1)
    locals_ = [pose(np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1))),
               pose(np.tile([0, -0.45, 0], (n, 1)), knee_q),
               pose(np.tile([0, -0.45, 0], (n, 1)), np.tile([1.0, 0, 0, 0], (n, 1)))]
    down = np.stack((rng.uniform(-0.4, 0.4, n), -np.ones(n), rng.uniform(-0.4, 0.4, n)), axis=1)
    target = rng.uniform(0.3, 0.88, (n, 1)) * down / np.linalg.norm(down, axis=1, keepdims=True)  # reachable (< 0.9)
    world = solved_chain(base, locals_, solve_two_bone(base, locals_, target, None))
    np.testing.assert_allclose(world[2].translation, target, atol=1e-9)
    hinge = quat_rotate(world[1].rotation, np.tile([0.0, 0.0, 1.0], (n, 1)))
    normal = np.cross(world[1].translation - world[0].translation, world[2].translation - world[1].translation)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", hinge, normal)), 1.0, atol=1e-9)


def test_unreachable_targets_stretch_towards_them_without_nan() -> None:
    rng = np.random.default_rng(2)
    n = 300
    base, locals_, l1, l2 = two_bone_chain(rng, n)
    root = chain_world(base, locals_)[0].translation
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    far = root + (l1 + l2)[:, None] * rng.uniform(1.01, 5.0, (n, 1)) * u
    world = solved_chain(base, locals_, solve_two_bone(base, locals_, far, None))
    end = world[2].translation
    assert np.isfinite(end).all()
    np.testing.assert_allclose(end, root + (l1 + l2)[:, None] * u, atol=1e-9)  # fully stretched, pointing at it
    # too close (inside |l1 - l2|) and exactly at the root: folded, finite
    near = root + (np.abs(l1 - l2) * 0.5)[:, None] * u
    for target in (near, root.copy()):
        world = solved_chain(base, locals_, solve_two_bone(base, locals_, target, None))
        assert all(np.isfinite(w.translation).all() and np.isfinite(w.rotation).all() for w in world)
        reach = np.linalg.norm(world[2].translation - root, axis=1)
        np.testing.assert_allclose(reach, np.abs(l1 - l2), atol=1e-9)


def arm(n: int) -> tuple[Pose, list[Pose]]:
    ident = np.tile([1.0, 0, 0, 0], (n, 1))
    base = pose(np.zeros((n, 3)), ident)
    down = lambda length: np.tile([0, -length, 0], (n, 1))  # noqa: E731
    return base, [pose(np.zeros((n, 3)), ident), pose(down(0.3), ident), pose(down(0.28), ident), pose(down(0.1), ident)]


def test_ccd_reaches_reachable_targets() -> None:
    rng = np.random.default_rng(3)
    n = 200
    base, locals_ = arm(n)
    u = rng.normal(size=(n, 3))
    target = rng.uniform(0.2, 0.6, (n, 1)) * u / np.linalg.norm(u, axis=1, keepdims=True)
    rot = solve_ccd(base, locals_, target, {}, iterations=200, tolerance=1e-6)
    end = solved_chain(base, locals_, rot)[-1].translation
    assert np.linalg.norm(end - target, axis=1).max() < 1e-4


def test_ccd_respects_hinge_and_cone_limits() -> None:
    rng = np.random.default_rng(4)
    n = 300
    base, locals_ = arm(n)
    target = rng.normal(size=(n, 3)) * 0.5
    limits = {
        0: JointLimit(joint="shoulder", cone=60.0),
        1: JointLimit(joint="elbow", axis=(0.0, 0.0, 1.0), min=0.0, max=150.0),
        2: JointLimit(joint="wrist", cone=30.0),
    }
    rot = solve_ccd(base, locals_, target, limits, iterations=64, tolerance=1e-6)
    assert all(np.isfinite(r).all() for r in rot)
    angle = lambda q: np.degrees(2 * np.arccos(np.clip(np.abs(q[:, 0]), 0, 1)))  # noqa: E731  (keyed locals are identity)
    assert angle(rot[0]).max() <= 60.0 + 1e-6
    assert angle(rot[2]).max() <= 30.0 + 1e-6
    elbow = rot[1] * np.sign(rot[1][:, :1] + 1e-300)
    np.testing.assert_allclose(elbow[:, 1:3], 0.0, atol=1e-12)  # about local Z only
    theta = np.degrees(2 * np.arctan2(elbow[:, 3], elbow[:, 0]))
    assert theta.min() >= -1e-6 and theta.max() <= 150.0 + 1e-6
    # the limits bind: some targets are not reached
    end = solved_chain(base, locals_, rot)[-1].translation
    assert np.linalg.norm(end - target, axis=1).max() > 0.05


def stairs(tmp_path: Path, edit: Any = None) -> Any:
    doc = yaml.safe_load((SCENES / "stairs-walk.yaml").read_text())
    if edit is not None:
        edit(doc)
    path = tmp_path / "stairs.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_scene(path), doc


def held_intervals(keys: list[dict]) -> list[tuple[float, float]]:
    return [(a["time"], b["time"]) for a, b in zip(keys, keys[1:]) if a["value"] == b["value"]]


def ground(x: np.ndarray) -> np.ndarray:
    """Top of the stairs at x: 0.15 m per 0.3 m step, the landing at 0.6 m from x = 0.9."""
    return np.where(x < 0, 0.0, np.minimum(np.floor(x / 0.3) + 1, 4) * 0.15)


def test_planted_feet_do_not_slide_or_sink_on_the_stairs(tmp_path: Path) -> None:
    loaded, doc = stairs(tmp_path)
    objects = {o["name"]: o for o in doc["objects"]}
    # frame times and sub-frame times across every shutter
    fps, last = 24, doc["timeline"]["last"]
    times = np.unique(np.concatenate([np.arange(last + 1) / fps + k / (4 * fps) for k in range(4)]))
    motion = evaluate(loaded, times)
    for side in ("l", "r"):
        keys = objects[f"foot_target_{side}"]["motion"]["channels"]["translate"]["keys"]
        ankle = motion.objects[f"ankle_{side}"].translation
        target = motion.objects[f"foot_target_{side}"].translation
        np.testing.assert_allclose(ankle, target, atol=1e-9)  # the ankle is on its target throughout
        for a, b in held_intervals(keys):
            inside = (times >= a) & (times <= b)
            assert inside.sum() >= 4
            travel = np.linalg.norm(ankle[inside] - ankle[inside][0], axis=1).max()
            assert travel < 1e-3, (side, a, b, travel)
        # the sole (the foot cube's bottom) never goes below the stairs under it
        foot = motion.objects[f"foot_{side}"]
        corners = np.array([[sx * 0.11, -0.03, sz * 0.05] for sx in (-1, 1) for sz in (-1, 1)])
        for c in corners:
            p = foot.translation + quat_rotate(foot.rotation, np.tile(c, (len(times), 1)))
            assert (p[:, 1] - ground(p[:, 0]) >= -1e-6).all()
        # and it stays flat (keep_effector_rotation)
        up = quat_rotate(foot.rotation, np.tile([0.0, 1.0, 0.0], (len(times), 1)))
        np.testing.assert_allclose(up, np.tile([0.0, 1.0, 0.0], (len(times), 1)), atol=1e-9)
    # the knees bend forward (towards the poles in front)
    knee = motion.objects["knee_l"].translation
    hip = motion.objects["hip_l"].translation
    ankle = motion.objects["ankle_l"].translation
    assert ((knee[:, 0] - (hip[:, 0] + ankle[:, 0]) / 2) > -1e-9).all()


def test_the_weight_curve_blends_with_the_keyed_pose(tmp_path: Path) -> None:
    loaded, doc = stairs(tmp_path)
    t = np.array([0.2, 0.7, 2.0])  # weight 0, 0.5, 1 on the reaching arm
    posed = evaluate(loaded, t)

    def no_arm_ik(d: dict) -> None:
        d["ik"] = d["ik"][:2]

    keyed = evaluate(stairs(tmp_path, no_arm_ik)[0], t)
    for name in ("shoulder_r", "elbow_r", "wrist_r", "hand_r"):
        np.testing.assert_allclose(posed.objects[name].rotation[0], keyed.objects[name].rotation[0], atol=1e-12)
    hand = posed.objects["hand_r"].translation
    lantern = posed.objects["lantern"].translation
    assert np.linalg.norm(hand[2] - lantern[2]) < 1e-3  # weight 1: it reaches the lantern
    # weight 0.5: the shoulder's local rotation is halfway (slerp) between keyed and solved
    q_half = posed.objects["shoulder_r"].rotation[1]
    q_key = keyed.objects["shoulder_r"].rotation[1]
    rel = quat_mul(quat_conj(q_key[None]), q_half[None])[0]
    assert 0 < 2 * np.degrees(np.arccos(min(1.0, abs(rel[0])))) < 140


@pytest.mark.parametrize(
    "edit, where, message",
    [
        (lambda d: d["ik"][0].update(chain=["hip_l", "ankle_l", "knee_l"]), "ik[0].chain[1]", "must be a child of 'hip_l'"),
        (lambda d: d["ik"][0].update(target="foot_targt_l"), "ik[0].target", "did you mean 'foot_target_l'"),
        (lambda d: d["ik"][0].update(target="shin_l"), "ik[0].target", "moves with the chain"),
        (lambda d: d["ik"][0].update(limits=[{"joint": "knee_l", "cone": 10}]), "ik[0]", "joint limits apply to the ccd solver"),
        (lambda d: d["ik"][2]["limits"][1].update(min=10, max=5), "ik[2].limits[1]", "min (10.0) exceeds max (5.0)"),
    ],
)
def test_bad_ik_is_a_located_error(tmp_path: Path, edit: Any, where: str, message: str) -> None:
    with pytest.raises(SceneError) as err:
        stairs(tmp_path, edit)
    text = str(err.value)
    assert "stairs.yaml:" in text and where in text and message in text, text
