"""Mover culling: each mover's bounding sphere is as tight as its shapes allow and never
culls a ray that can hit it (world.py skips a mover's BVH call for packets of rays that
all miss its sphere, so a sphere too small would drop hits and one too big costs time)."""

from __future__ import annotations

import numpy as np
import pytest

from _render_support import activate

pytestmark = pytest.mark.render


def _mover(shape: dict) -> object:
    import mitsuba as mi

    return mi.load_dict({"type": "scene", "s": shape})


def test_bounding_spheres_are_as_tight_as_the_shapes() -> None:
    activate()
    from motion.pipeline.render.poses import bounding_spheres

    sphere = _mover({"type": "sphere", "radius": 0.5, "center": [1.0, 2.0, 3.0]})
    cube = _mover({"type": "cube"})  # a mesh: corners at distance sqrt(3)
    disk = _mover({"type": "disk"})  # neither: the farthest corner of its box
    got = bounding_spheres([sphere, cube, disk])
    np.testing.assert_allclose(got[0, :3], [1.0, 2.0, 3.0], atol=1e-6)
    assert 0.5 < got[0, 3] < 0.5 * 1.001  # the sphere itself, not its box's sphere (0.87)
    assert np.sqrt(3.0) < got[1, 3] < np.sqrt(3.0) * 1.001
    assert np.sqrt(2.0) <= got[2, 3] < np.sqrt(2.0) * 1.001


def test_a_grazing_ray_is_kept_and_a_near_miss_is_culled() -> None:
    activate()
    import drjit as dr
    import mitsuba as mi

    from motion.pipeline.render.poses import bounding_spheres, may_hit

    mover = _mover({"type": "sphere", "radius": 0.5})
    c = bounding_spheres([mover])[0]
    sphere = (mi.Vector3f(*(float(v) for v in c[:3])), dr.square(mi.Float(float(c[3]))))
    offsets = [0.0, 0.4999, 0.55, 0.8]  # rays along +Z passing this far from the centre
    ray = mi.Ray3f(mi.Point3f(mi.Float(offsets), 0.0, -5.0), mi.Vector3f(0.0, 0.0, 1.0))
    near = np.array(may_hit(sphere, ray, mi.Bool(True)), dtype=bool)
    hits = np.array(mover.ray_intersect_preliminary(ray).is_valid(), dtype=bool)
    assert hits.tolist() == [True, True, False, False]
    assert near.tolist() == [True, True, False, False]  # the box's sphere (0.87) kept 0.55 and 0.8


def test_the_swept_sphere_holds_the_mover_at_every_time_of_the_shutter() -> None:
    """world.py tests a ray against a mover's swept sphere before it poses the mover at
    the ray's time: the sphere must hold the posed bounding sphere at every u, also for a
    rest centre off the origin that swings through large rotations between samples."""
    from motion.pipeline.motion.pose import quat_exp, quat_rotate
    from motion.pipeline.render.poses import swept_spheres
    from motion.pipeline.render.shutter_poses import resample

    rng = np.random.default_rng(7)
    n = 5
    axis = np.array([0.3, 1.0, -0.4]) / np.linalg.norm([0.3, 1.0, -0.4])
    q = quat_exp(np.outer(np.linspace(0.0, 4.0, n), axis))  # 1 rad between samples
    t = np.cumsum(rng.normal(size=(n, 3)), axis=0) + [500.0, 0.0, 0.0]  # far from the origin
    rest = np.array([[0.3, -0.2, 0.5, 0.4]])
    swept = swept_spheres(t[None], q[None], rest)[0]
    reach = 0.0
    for u in np.linspace(0.0, 1.0, 801):
        tt, qq = resample(t, q, float(u))
        centre = quat_rotate(qq, rest[0, :3]) + tt
        reach = max(reach, float(np.linalg.norm(centre - swept[:3])) + rest[0, 3])
    assert reach <= swept[3]
    assert swept[3] < 1.2 * reach  # and not much bigger than the path it holds


def test_a_still_mover_sweeps_its_own_sphere() -> None:
    from motion.pipeline.render.poses import swept_spheres

    n = 9
    t = np.tile([1.0, 2.0, 3.0], (1, n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (1, n, 1))
    swept = swept_spheres(t, q, np.array([[0.0, 0.0, 0.0, 0.5]]))[0]
    np.testing.assert_allclose(swept[:3], [1.0, 2.0, 3.0])
    assert 0.5 < swept[3] < 0.5 * 1.001


def test_movers_near_the_camera_are_posed_once_per_path() -> None:
    """`eager_movers` picks the movers whose swept sphere covers a good share of the image
    (posed once per path) and leaves small, far ones on demand; only speed depends on it."""
    from motion.pipeline.render.poses import eager_movers

    scale = (320 / 2) / np.tan(np.radians(50) / 2)  # perspective, 320 px across a 50 degree view
    swept = np.array([[0.0, 0.0, -2.0, 0.5], [0.0, 0.0, -40.0, 0.5], [0.0, 0.0, 0.0, 1.0]])
    got = eager_movers(swept, np.zeros(3), ("perspective", scale), 320 * 180)
    assert got == [True, False, True]  # close-up; far and small; the camera inside it
    assert eager_movers(swept[:2], np.zeros(3), ("orthographic", 320 / 100.0), 320 * 180) == [False, False]
