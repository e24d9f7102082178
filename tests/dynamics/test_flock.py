"""Flocks (pipeline/dynamics/flock.py): separation holds after settling, agents face along
their velocity, obstacles and bounds are respected, crowds stay planar, seeded and baked
like every other motion source, bad input is a located error."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from _dynamics_scenes import write_scene
from _support import SCENES, run_motion
from motion.pipeline.bake import bake
from motion.pipeline.dynamics import simulate
from motion.pipeline.dynamics.flock import FlockParams, simulate_flock
from motion.pipeline.motion.instances import facing_frames
from motion.pipeline.scene import load_scene


def flock_object(**spec: Any) -> dict[str, Any]:
    block = {"type": "flock", "count": 40, "seed": 3, "spawn_center": [0, 2, 0], "spawn_size": [1.0, 1.0, 1.0], **spec}
    return {"name": "birds", "shape": "cube", "size": [0.04, 0.02, 0.12], "deform": block}


def test_no_two_agents_closer_than_the_separation_after_settling(tmp_path: Path) -> None:
    # 40 agents start packed in a 1 m cube (closer than 0.3 m), in a 10 m box that has room
    bounds = {"min": [-5, -3, -5], "max": [5, 7, 5]}
    path = write_scene(tmp_path, [flock_object(separation=0.3, bounds=bounds, neighbour_radius=1.5)], last=48)
    track = simulate(load_scene(path), 2.0).flock("birds")
    start = pdist(track.x[0].astype(np.float64)).min()
    assert start < 0.3  # the case needs separating
    settled = track.times >= 0.5
    worst = min(pdist(x.astype(np.float64)).min() for x in track.x[settled])
    assert worst >= 0.3 * (1 - 1e-5), worst
    # and they stay a flock: every agent has a neighbour within the neighbour radius
    final = track.x[-1].astype(np.float64)
    d = np.linalg.norm(final[:, None] - final[None], axis=2) + np.eye(40) * 1e9
    assert d.min(axis=1).max() < 1.5


def test_agents_face_along_their_velocity(tmp_path: Path) -> None:
    path = write_scene(tmp_path, [flock_object(goal=[5, 2, 0])], last=24)
    loaded = load_scene(path)
    baked = bake(loaded, [12])
    frame = baked.frames[0]
    verts = frame.across_shutter.vertices["birds"]  # [N, count * 24, 3] (a cube at detail 1: 24 vertices)
    assert verts.shape == (9, 40 * 24, 3)
    x, v = simulate(loaded, 1.0).flock("birds").at(frame.sample_times)
    agents = verts.reshape(9, 40, 24, 3)
    centre = agents.mean(axis=2)
    np.testing.assert_allclose(centre, x, atol=1e-5)
    # in each agent's facing frame the cube is 0.04 x 0.02 x 0.12: its long side (local
    # +Z) lies along the velocity
    frames = facing_frames(v, np.array([0.0, 1.0, 0.0]))
    local = np.einsum("tnji,tnvj->tnvi", frames, agents - centre[:, :, None])  # agent space
    extent = local.max(axis=2) - local.min(axis=2)
    np.testing.assert_allclose(extent, np.broadcast_to([0.04, 0.02, 0.12], extent.shape), atol=1e-6)
    unit_v = v / np.linalg.norm(v, axis=2, keepdims=True)
    np.testing.assert_allclose(frames[..., 2], unit_v, atol=1e-9)


def test_facing_frames_are_rotations_and_handle_velocity_along_up() -> None:
    rng = np.random.default_rng(1)
    v = rng.normal(size=(200, 3))
    v[0] = [0, 2, 0]  # straight up
    v[1] = [0, 0, 0]  # at rest
    r = facing_frames(v, np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    np.testing.assert_allclose(r[0, :, 2], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(r[1], np.eye(3))
    # level flight keeps local +Y up
    level = facing_frames(np.array([[1.0, 0.0, 1.0]]), np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(level[0, :, 1], [0, 1, 0], atol=1e-12)


def test_obstacles_are_avoided_and_never_entered(tmp_path: Path) -> None:
    rock = {"name": "rock", "shape": "sphere", "radius": 0.8, "collider": {}, "transform": {"translate": [2.5, 2, 0]}}
    spec = flock_object(goal=[6, 2, 0], count=30, spawn_center=[-1, 2, 0], max_speed=3.0, avoid_distance=0.8)
    path = write_scene(tmp_path, [spec, rock], last=108)
    track = simulate(load_scene(path), 4.5).flock("birds")
    dist = np.linalg.norm(track.x.astype(np.float64) - [2.5, 2, 0], axis=2)
    assert dist.min() >= 0.8 - 1e-4
    # they did pass the rock on the way to the goal
    assert (track.x[-1, :, 0] > 3.3).mean() > 0.8


def test_planar_crowd_stays_on_its_plane_and_is_seeded(tmp_path: Path) -> None:
    spec = flock_object(planar=True, goal=[4, 0.5, 3], spawn_center=[0, 0.5, 0], spawn_size=[3, 3, 3], count=60)
    path = write_scene(tmp_path, [spec], last=24)
    a = simulate(load_scene(path), 1.0).flock("birds")
    b = simulate(load_scene(path), 1.0).flock("birds")
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_allclose(a.x[..., 1], 0.5, atol=1e-5)
    np.testing.assert_allclose(a.v[..., 1], 0.0, atol=1e-5)


def test_speed_stays_within_its_limits() -> None:
    spec = load_spec(count=100, min_speed=0.5, max_speed=1.5, speed=1.0)
    track = simulate_flock(FlockParams.from_spec(spec), [], 0.0, 1.0)
    speed = np.linalg.norm(track.v[1:].astype(np.float64), axis=2)
    assert speed.min() >= 0.5 - 1e-5 and speed.max() <= 1.5 + 1e-5


def load_spec(**fields: Any) -> Any:
    from motion.pipeline.scene.motion_schema import Flock

    return Flock(type="flock", **fields)


def test_bad_flock_is_a_located_error(tmp_path: Path) -> None:
    path = write_scene(tmp_path, [flock_object(min_speed=3.0, max_speed=1.0)])
    proc = run_motion("validate", str(path))
    assert proc.returncode == 2
    assert "objects[0].deform" in proc.stderr and "min_speed (3.0) exceeds max_speed (1.0)" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_flock_example_validates_and_bakes(tmp_path: Path) -> None:
    proc = run_motion("validate", str(SCENES / "flock.yaml"))
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "flock.npz"
    proc = run_motion("bake", str(SCENES / "flock.yaml"), "--frames", "0-3", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    with np.load(out) as z:
        verts = z["samples/vertices/darts"]
    assert verts.shape[:2] == (4, 9) and verts.shape[2] == 240 * 5
    assert np.isfinite(verts).all()


@pytest.mark.parametrize("count", [1, 2])
def test_tiny_flocks_work(count: int) -> None:
    track = simulate_flock(FlockParams.from_spec(load_spec(count=count)), [], 0.0, 0.2)
    assert track.x.shape[1] == count and np.isfinite(track.x).all()


def test_too_many_instance_vertices_is_a_located_error(tmp_path: Path) -> None:
    from motion.pipeline.errors import SceneError

    path = write_scene(tmp_path, [flock_object(count=200_000)], last=0)
    with pytest.raises(SceneError) as err:
        bake(load_scene(path), [0])
    assert "objects[0].deform.count" in str(err.value) and "more than 4000000 vertices" in str(err.value)


def test_a_flock_of_spheres_is_a_located_error(tmp_path: Path) -> None:
    from motion.pipeline.errors import SceneError

    obj = flock_object()
    obj.update(shape="sphere", radius=0.05)
    del obj["size"]
    path = write_scene(tmp_path, [obj], last=0)
    with pytest.raises(SceneError) as err:
        bake(load_scene(path), [0])
    assert "objects[0].deform" in str(err.value) and "sphere is not supported" in str(err.value)


AGENT_SHAPES = {
    "cube": {"shape": "cube", "size": [0.04, 0.02, 0.12]},
    "cylinder": {"shape": "cylinder", "radius": 0.03, "height": 0.1},
    "capsule": {"shape": "capsule", "radius": 0.02, "height": 0.08},
    "mesh": {"shape": "mesh", "file": str(SCENES / "assets" / "dart.obj")},
}


@pytest.mark.parametrize("shape", list(AGENT_SHAPES))
def test_every_agent_shape_bakes_solid(tmp_path: Path, shape: str) -> None:
    """Each agent's baked vertices span three dimensions (a cylinder agent is a closed
    cylinder, not a flat card seen edge-on): the thinnest principal extent of each agent is
    at least a tenth of its longest (the 0.04 x 0.02 x 0.12 cube: a sixth; a card: 0)."""
    obj = {**{k: v for k, v in flock_object(count=6).items() if k not in ("shape", "size")}, **AGENT_SHAPES[shape]}
    loaded = load_scene(write_scene(tmp_path, [obj], last=4))
    frame = bake(loaded, [2]).frames[0]
    verts = frame.across_shutter.vertices["birds"]
    agents = verts.reshape(len(verts), 6, -1, 3)[0]  # [agents, V, 3] at the first sample
    centred = agents - agents.mean(axis=1, keepdims=True)
    singular = np.linalg.svd(centred, compute_uv=False)  # [agents, 3]
    assert (singular[:, 2] > 0.1 * singular[:, 0]).all(), singular
