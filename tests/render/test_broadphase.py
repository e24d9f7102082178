"""The broadphase and the atlas (render/kernel/broadphase.py, render/kernel/atlas.py): every proxy holds
its mover or particle at every time of the shutter, bounding spheres are as tight as the
shapes allow and never cull a ray that can hit, coincident proxies are made apart (the
walk steps past each entry it visits), and the atlas's cells never overlap."""

from __future__ import annotations

import numpy as np
import pytest

from _render_support import activate

pytestmark = pytest.mark.render


def _shape(shape: dict) -> object:
    import mitsuba as mi

    return mi.load_dict(shape)


def _spheres(shapes: list) -> np.ndarray:
    """The atlas's rest-frame bounding sphere of each one-shape template."""
    from motion.pipeline.render.kernel.atlas import Atlas

    import mitsuba as mi

    atlas = Atlas(mi, lambda d: mi.load_dict(d))
    atlas.build([[s] for s in shapes], [f"t{k}" for k in range(len(shapes))])
    return atlas.layout.sphere


def test_bounding_spheres_are_as_tight_as_the_shapes() -> None:
    activate()
    sphere = _shape({"type": "sphere", "radius": 0.5, "center": [1.0, 2.0, 3.0]})
    cube = _shape({"type": "cube"})  # a mesh: corners at distance sqrt(3)
    disk = _shape({"type": "disk"})  # neither: the farthest corner of its box
    got = _spheres([sphere, cube, disk])
    np.testing.assert_allclose(got[0, :3], [1.0, 2.0, 3.0], atol=1e-6)
    assert 0.5 < got[0, 3] < 0.5 * 1.001  # the sphere itself, not its box's sphere (0.87)
    assert np.sqrt(3.0) < got[1, 3] < np.sqrt(3.0) * 1.001
    assert np.sqrt(2.0) <= got[2, 3] < np.sqrt(2.0) * 1.001


def test_a_grazing_ray_is_kept_and_a_near_miss_is_culled() -> None:
    activate()
    import drjit as dr
    import mitsuba as mi

    from motion.pipeline.render.poses.kernel import may_hit

    mover = mi.load_dict({"type": "scene", "s": {"type": "sphere", "radius": 0.5}})
    c = _spheres([_shape({"type": "sphere", "radius": 0.5})])[0]
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
    from motion.pipeline.render.kernel.broadphase import swept_spheres
    from motion.pipeline.render.poses.shutter import resample

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
    from motion.pipeline.render.kernel.broadphase import swept_spheres

    n = 9
    t = np.tile([1.0, 2.0, 3.0], (1, n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (1, n, 1))
    swept = swept_spheres(t, q, np.array([[0.0, 0.0, 0.0, 0.5]]))[0]
    np.testing.assert_allclose(swept[:3], [1.0, 2.0, 3.0])
    assert 0.5 < swept[3] < 0.5 * 1.001


def test_a_particles_proxy_holds_it_at_every_time_of_the_shutter() -> None:
    """A particle's ellipsoid holds its sphere along the whole baked path (a bent one
    too), and is not much larger than the capsule the path sweeps."""
    from motion.pipeline.motion.pose import quat_rotate
    from motion.pipeline.render.kernel.broadphase import particle_proxies

    n = 9
    s = np.linspace(0.0, 1.0, n)
    path = np.stack([3.0 * s, 1.0 - 0.5 * s**2, 0.2 * s], axis=1)  # fast, bending down
    radius = 0.05
    proxy = particle_proxies(path[None], np.ones((1, n), bool), np.array([radius]))[0]
    centre, semi, q = proxy[:3], proxy[3:6], proxy[6:10]
    q_wxyz = np.array([q[3], q[0], q[1], q[2]])
    inverse = q_wxyz * np.array([1.0, -1.0, -1.0, -1.0])
    for u in np.linspace(0.0, 1.0, 401):
        x = u * (n - 1)
        i = min(int(x), n - 2)
        c = path[i] + (x - i) * (path[i + 1] - path[i])
        for d in np.eye(3).tolist() + (-np.eye(3)).tolist():  # the sphere's extreme points
            local = quat_rotate(inverse, c + radius * np.array(d) - centre)
            assert float(np.sum((local / semi) ** 2)) <= 1.0
    length = np.linalg.norm(path[-1] - path[0])
    assert semi[0] < np.sqrt(2.0) * (length / 2 + radius + 0.2)  # the chord's half, the bend, the radius


def test_coincident_proxies_are_made_apart() -> None:
    """The parts of one rigid body share one swept sphere: `separate` grows each by a rank
    so their entries differ by more than the walk's step; distinct proxies stay as they are."""
    from motion.pipeline.render.kernel.broadphase import separate, sphere_proxies

    spheres = np.array([[1.0, 2.0, 3.0, 0.5]] * 3 + [[5.0, 0.0, 0.0, 0.5]])
    out = separate(sphere_proxies(spheres), scale=100.0)
    radii = np.sort(out[:3, 3])
    step = 2e-7 * 100.0 + 1e-7
    assert np.all(np.diff(radii) > 2 * step)
    np.testing.assert_array_equal(out[3], sphere_proxies(spheres)[3])


def test_the_frames_time_in_the_shutters_middle_keeps_a_particles_proxy_along_its_path() -> None:
    """The renderer bounds every baked row: the N shutter samples and the frame's time,
    which a centred shutter puts in their middle. Taken as the chord's first end, the
    chord covered half the path and the sample at the shutter's opening lay half a path
    off it: the proxy became a sphere as wide as the path (cannonball-splash's spray,
    2.3x across, and its splash frames 2.3x slower). The frame's time is held, not an end."""
    from motion.pipeline.render.kernel.broadphase import particle_proxies

    path = np.linspace([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 9)[None]  # [1, N, 3]: 1 m along x
    alive = np.ones((1, 9), bool)
    middle = (path[:, 4], np.ones(1, bool))
    (proxy,) = particle_proxies(path, alive, np.array([0.03]), middle)
    np.testing.assert_allclose(proxy[:3], [0.5, 0.0, 0.0], atol=1e-9)
    assert proxy[3] < np.sqrt(2.0) * (0.5 + 0.03) * 1.01  # along the path
    assert proxy[4] < np.sqrt(2.0) * 0.03 * 1.01  # across it: the particle's own width
    # a particle alive only at the frame's time is held there
    (born,) = particle_proxies(path, np.zeros((1, 9), bool), np.array([0.03]), middle)
    np.testing.assert_allclose(born[:3], path[0, 4], atol=1e-9)


def test_distinct_proxies_stay_tight_whatever_the_walks_scale() -> None:
    """A spray's particles a few millimetres apart are not coincident, however far the
    walk reaches: with cannonball-splash's 20 km sea (a walk scale of 35 km) they were
    grouped by that scale into one run and grown by up to 9 m each, and one frame of the
    spray took minutes. Only centres within float steps of each other are made apart."""
    from motion.pipeline.render.kernel.broadphase import separate, sphere_proxies

    rng = np.random.default_rng(5)
    centres = np.array([2.0, 0.05, -12.0]) + rng.uniform(-1.0, 1.0, size=(2000, 3))
    spheres = np.concatenate([centres, np.full((2000, 1), 0.03)], axis=1)
    spheres[1:4] = spheres[0]  # four at one point (born together): made apart
    out = separate(sphere_proxies(spheres), scale=35_000.0)
    np.testing.assert_array_equal(out[4:], sphere_proxies(spheres)[4:])
    radii = np.sort(out[:4, 3])
    assert np.all(np.diff(radii) > 2 * (2e-7 * 35_000.0 + 1e-7))


def test_the_atlas_cells_never_overlap() -> None:
    from motion.pipeline.render.kernel.atlas import lay_out

    rng = np.random.default_rng(3)
    lo = rng.normal(size=(50, 3)) * 10
    boxes = np.stack([lo, lo + rng.uniform(0.01, 3.0, size=(50, 3))], axis=1)
    layout = lay_out(boxes, np.zeros((50, 4)))
    a, b = layout.box[:, None], layout.box[None, :]
    overlap = np.all((a[..., 0, :] < b[..., 1, :]) & (b[..., 0, :] < a[..., 1, :]), axis=-1)
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    np.testing.assert_allclose(boxes + layout.offset[:, None], np.clip(boxes + layout.offset[:, None], layout.box[:, :1], layout.box[:, 1:]))
