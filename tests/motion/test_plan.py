"""Motion planning (pipeline/motion/plan.py): A* is optimal, the path and its simulated
follower keep the agent radius from every wall at any time (sub-frame times included),
the follower stays within its stated tolerance of the path, no path is a located error."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from _support import SCENES, run_motion
from motion.pipeline.bake import bake
from motion.pipeline.dynamics import simulate
from motion.pipeline.errors import SceneError
from motion.pipeline.motion import evaluate
from motion.pipeline.motion.plan import Grid, astar, plan_for
from motion.pipeline.scene import load_scene


def reference_cost(blocked: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """Dijkstra (scipy) over the same 8-connected graph: the independent optimum."""
    rows, cols = blocked.shape
    src, dst, w = [], [], []
    for r in range(rows):
        for c in range(cols):
            if blocked[r, c]:
                continue
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1), (0, -1), (-1, 0), (-1, -1), (-1, 1)):
                nr, nc = r + dr, c + dc
                if not (0 <= nr < rows and 0 <= nc < cols) or blocked[nr, nc]:
                    continue
                if dr and dc and (blocked[r, nc] or blocked[nr, c]):
                    continue
                src.append(r * cols + c)
                dst.append(nr * cols + nc)
                w.append(math.sqrt(2.0) if dr and dc else 1.0)
    graph = coo_matrix((w, (src, dst)), shape=(rows * cols, rows * cols)).tocsr()
    return float(dijkstra(graph, indices=start[0] * cols + start[1])[goal[0] * cols + goal[1]])


def test_astar_cost_on_an_open_grid_is_the_octile_distance() -> None:
    blocked = np.zeros((20, 30), dtype=bool)
    path, cost = astar(blocked, (2, 3), (9, 27))
    assert cost == pytest.approx(7 * math.sqrt(2) + 17, abs=1e-12)
    steps = np.abs(np.diff(np.asarray(path), axis=0))
    assert steps.max() == 1 and (steps.sum(axis=1) > 0).all()


def test_astar_around_a_wall_with_a_gap_matches_the_known_answer() -> None:
    # a wall across column 5 with a gap at row 9: from (0, 0) to (0, 10)
    blocked = np.zeros((10, 11), dtype=bool)
    blocked[:9, 5] = True
    _, cost = astar(blocked, (0, 0), (0, 10))
    # down to the gap and back up: (0,0) -> (8,4) is 4 diagonal + 4 straight, then through
    # (9,5) needs the corner rule: (8,4) -> (9,4) -> (9,5) -> (9,6) -> (8,6), then (8,6) -> (0,10)
    # is 4 diagonal + 4 straight: 2 (4 sqrt2 + 4) + 4
    assert cost == pytest.approx(8 * math.sqrt(2) + 12, abs=1e-12)
    assert cost == pytest.approx(reference_cost(blocked, (0, 0), (0, 10)), abs=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_astar_is_optimal_on_random_grids(seed: int) -> None:
    rng = np.random.default_rng(seed)
    blocked = rng.random((24, 24)) < 0.3
    blocked[0, 0] = blocked[23, 23] = False
    found = astar(blocked, (0, 0), (23, 23))
    ref = reference_cost(blocked, (0, 0), (23, 23))
    if found is None:
        assert math.isinf(ref)
    else:
        assert found[1] == pytest.approx(ref, abs=1e-9)


def wall_distance(grid: Grid, xz: np.ndarray) -> np.ndarray:
    """Brute force: distance from each point to every wall square of the grid and to the
    space outside it."""
    r, c = np.nonzero(grid.wall)
    lo = grid.origin + np.stack((c, r), axis=1) * grid.cell
    hi = lo + grid.cell
    d = np.maximum(np.maximum(lo[None] - xz[:, None], xz[:, None] - hi[None]), 0.0)
    inside = np.linalg.norm(d, axis=2).min(axis=1)
    extent = grid.origin + np.array(grid.wall.shape[::-1]) * grid.cell
    border = np.minimum(np.min(xz - grid.origin, axis=1), np.min(extent - xz, axis=1))
    return np.minimum(inside, border)


def box_distance(xz: np.ndarray, centre: tuple[float, float], size: tuple[float, float]) -> np.ndarray:
    d = np.maximum(np.abs(xz - np.asarray(centre)) - np.asarray(size) / 2, 0.0)
    return np.linalg.norm(d, axis=1)


def drone_scene(tmp_path: Path, follower: bool = True) -> Path:
    doc = yaml.safe_load((SCENES / "drone-corridors.yaml").read_text())
    if not follower:
        for o in doc["objects"]:
            if o["name"] == "drone":
                del o["motion"]["follower"]
    path = tmp_path / "drone.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def drone(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, Any]:
    loaded = load_scene(SCENES / "drone-corridors.yaml")
    return loaded, simulate(loaded, 12.6)


def test_the_follower_keeps_the_radius_from_every_wall_at_any_time(drone: tuple[Any, Any]) -> None:
    loaded, sim = drone
    index = [o.name for o in loaded.scene.objects].index("drone")
    rng = np.random.default_rng(0)
    times = np.sort(np.concatenate((rng.uniform(0.0, 12.6, 3000), np.arange(0, 12.6, 1 / 48))))  # sub-frame times
    pose = evaluate(loaded, times, sim).objects["drone"]
    xz = pose.translation[:, [0, 2]]
    path = plan_for(loaded, index)
    radius = loaded.scene.objects[index].motion.radius
    assert wall_distance(path.grid, xz).min() >= radius
    # and from the real geometry the grid was projected from (the cubes' footprints)
    for o in loaded.scene.objects:
        if o.shape == "cube" and o.name.startswith(("wall", "baffle")):
            centre = (o.transform.translate[0], o.transform.translate[2])
            assert box_distance(xz, centre, (o.size[0], o.size[2])).min() >= radius, o.name
    pillar = np.linalg.norm(xz - [-4.0, 1.0], axis=1) - 0.5
    assert pillar.min() >= radius
    # it did fly: start to goal, and hovered at its height
    np.testing.assert_allclose(pose.translation[0], [-4.5, 1.2, -3.5], atol=1e-6)
    assert np.linalg.norm(pose.translation[-1] - [4.5, 1.2, 3.5]) < 0.02
    assert np.abs(pose.translation[:, 1] - 1.2).max() < 0.02


def test_the_follower_stays_within_its_tolerance_of_the_path(drone: tuple[Any, Any]) -> None:
    loaded, sim = drone
    index = [o.name for o in loaded.scene.objects].index("drone")
    path = plan_for(loaded, index)
    times = np.linspace(0.0, 12.6, 3001)
    x = evaluate(loaded, times, sim).objects["drone"].translation
    # exact distance to the dense path polyline: the segments next to the 8 nearest samples
    p = path.samples()
    _, near = cKDTree(p).query(x, k=8)
    k = np.clip(np.concatenate((near, near - 1), axis=1), 0, len(p) - 2)
    a, ab = p[k], p[k + 1] - p[k]
    s = np.clip(np.einsum("tkj,tkj->tk", x[:, None] - a, ab) / np.maximum(np.einsum("tkj,tkj->tk", ab, ab), 1e-18), 0, 1)
    d = np.linalg.norm(a + s[..., None] * ab - x[:, None], axis=2).min(axis=1)
    assert d.max() <= 0.1  # the stated tolerance
    # it is a real simulation, not the reference itself: it lags and deviates a little
    assert d.max() > 1e-4


def test_the_kinematic_path_keeps_the_radius_and_its_speed_profile(tmp_path: Path) -> None:
    loaded = load_scene(drone_scene(tmp_path, follower=False))
    index = [o.name for o in loaded.scene.objects].index("drone")
    spec = loaded.scene.objects[index].motion
    path = plan_for(loaded, index)
    times = np.linspace(-0.5, path.duration + 0.5, 6001)
    x = evaluate(loaded, times).objects["drone"].translation
    assert wall_distance(path.grid, x[:, [0, 2]]).min() >= spec.radius
    v = np.linalg.norm(np.diff(x, axis=0), axis=1) / np.diff(times)
    assert v.max() <= spec.speed * (1 + 1e-3)
    assert v.max() >= spec.speed * 0.99  # it cruises
    acc = np.abs(np.diff(path.arc(times), 2)) / np.diff(times)[0] ** 2
    assert acc.max() <= spec.accel * (1 + 1e-6) + 1e-9
    np.testing.assert_allclose(x[0], spec.start, atol=1e-9)
    np.testing.assert_allclose(x[-1], spec.goal, atol=1e-9)
    # the A* legs' cost is the optimum on the inflated grid
    blocked = path.grid.blocked(spec.radius + (spec.margin or path.grid.cell))
    cells = path.cells[0]
    assert path.costs[0] == pytest.approx(reference_cost(blocked, cells[0], cells[-1]) * path.grid.cell, abs=1e-9)


def test_banking_leans_into_the_turn(tmp_path: Path) -> None:
    loaded = load_scene(drone_scene(tmp_path, follower=False))
    index = [o.name for o in loaded.scene.objects].index("drone")
    path = plan_for(loaded, index)
    t = np.linspace(0.5, path.duration - 0.5, 400)
    h = 5e-3
    p0, p1, p2 = path.position(t - h), path.position(t), path.position(t + h)
    a = (p2 - 2 * p1 + p0) / h**2  # the path's own acceleration, by finite differences
    a -= np.einsum("ij,ij->i", a, path.tangent(t))[:, None] * path.tangent(t)  # across the heading
    pose = evaluate(loaded, t).objects["drone"]
    from motion.pipeline.motion.pose import quat_rotate

    up = quat_rotate(pose.rotation, np.tile([0.0, 1.0, 0.0], (len(t), 1)))
    turning = np.linalg.norm(a[:, [0, 2]], axis=1) > 0.5
    assert turning.sum() > 10
    lean = np.einsum("ij,ij->i", up[turning][:, [0, 2]], a[turning][:, [0, 2]])
    assert (lean > 0).all()
    expected = np.degrees(np.arctan(np.linalg.norm(a[turning][:, [0, 2]], axis=1) / 9.81))
    got = np.degrees(np.arccos(np.clip(up[turning][:, 1], -1, 1)))
    gentle = expected < 25  # finite differences blur the sharpest corners
    np.testing.assert_allclose(got[gentle], expected[gentle], atol=1.0)
    assert got.max() > 30


def image_scene(tmp_path: Path, closed: bool) -> Path:
    from PIL import Image

    img = np.full((40, 60), 255, dtype=np.uint8)
    img[:, 28:32] = 0  # a wall down the middle
    if not closed:
        img[30:38, 28:32] = 255  # with a gap near the bottom
    Image.fromarray(img).save(tmp_path / "map.png")
    doc = {
        "name": "maze",
        "timeline": {"fps": 24, "first": 0, "last": 10},
        "camera": {"position": [3, 8, 2], "look_at": [3, 0, 2]},
        "objects": [{
            "name": "bot", "shape": "sphere", "radius": 0.2,
            "motion": {"type": "plan", "grid": {"image": "map.png", "cell": 0.1},
                       "start": [0.5, 0.2, 0.5], "goal": [5.5, 0.2, 0.5], "radius": 0.2, "speed": 1.0},
        }],
    }
    path = tmp_path / "maze.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_an_image_grid_plans_through_its_gap(tmp_path: Path) -> None:
    loaded = load_scene(image_scene(tmp_path, closed=False))
    path = plan_for(loaded, 0)
    samples = path.samples()
    assert samples[:, 2].max() > 3.0  # down through the gap (rows 30..37 = z 3.0..3.8)
    assert wall_distance(path.grid, samples[:, [0, 2]]).min() >= 0.2


def test_no_path_is_a_located_error_naming_start_and_goal(tmp_path: Path) -> None:
    scene = image_scene(tmp_path, closed=True)
    with pytest.raises(SceneError) as err:
        bake(load_scene(scene), [0])
    text = str(err.value)
    assert "maze.yaml:" in text and "objects[0].motion" in text
    assert "no path from start (0.5, 0.2, 0.5) to goal (5.5, 0.2, 0.5)" in text
    proc = run_motion("bake", str(scene), "-o", str(tmp_path / "m.json"))
    assert proc.returncode == 2 and "no path from start" in proc.stderr and "Traceback" not in proc.stderr


def test_a_start_inside_a_wall_is_located_at_the_start(tmp_path: Path) -> None:
    scene = image_scene(tmp_path, closed=False)
    doc = yaml.safe_load(scene.read_text())
    doc["objects"][0]["motion"]["start"] = [3.0, 0.2, 1.0]
    scene.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(SceneError) as err:
        evaluate(load_scene(scene), np.array([0.0]))
    assert "objects[0].motion.start" in str(err.value) and "from a wall" in str(err.value)


def test_a_plan_on_the_camera_is_refused(tmp_path: Path) -> None:
    scene = image_scene(tmp_path, closed=False)
    doc = yaml.safe_load(scene.read_text())
    doc["camera"]["motion"] = dict(doc["objects"][0]["motion"])
    scene.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    assert "camera.motion.type" in str(err.value) and "objects only" in str(err.value)


def test_a_plan_with_no_margin_in_a_corridor_is_refused_in_bounded_time() -> None:
    """margin 0 in a corridor exactly the agent's width: each refinement round doubled the
    spline's vertices (42 -> 100,904 in 13 rounds) and the bake never finished."""
    import time

    from motion.pipeline.motion.plan import Grid, _Located, build_path

    wall = np.ones((60, 60), bool)
    wall[10:15, 5:46] = False
    wall[10:51, 41:46] = False
    t0 = time.perf_counter()
    with pytest.raises(_Located, match="give a larger margin"):
        build_path(Grid(wall, 0.1, np.array([0.0, 0.0])), [[0.75, 0.0, 1.25], [4.35, 0.0, 4.8]], 0.25, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, "none")
    assert time.perf_counter() - t0 < 10
