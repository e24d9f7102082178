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
