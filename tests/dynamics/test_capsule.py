"""The capsule: a shape added as one schema record plus one geometry entry
(pipeline/geometry.py), seen by every stage: it renders, has the closed-form inertia, a
bound and a volume, collides (a static capsule is a mesh collider; a capsule body collides
as its bounding sphere), deforms and blocks planned paths."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from _dynamics_scenes import ball, floor, run, write_scene
from _render_support import column_x, load, render

from motion.pipeline.geometry import principal_inertia, shape_geometry, tessellate
from motion.pipeline.scene import load_scene

R, H = 0.5, 1.0  # radius, length of the cylindrical part (the caps' centres at +-H/2)


def _capsule_points(n: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform points of the solid capsule (rejection from its bounding box)."""
    box = rng.uniform(-1, 1, size=(n, 3)) * np.array([R, H / 2 + R, R])
    y = np.clip(box[:, 1], -H / 2, H / 2)
    inside = box[:, 0] ** 2 + (box[:, 1] - y) ** 2 + box[:, 2] ** 2 <= R * R
    return box[inside]


def test_inertia_matches_the_volume_integral() -> None:
    # I_xx = m <y^2 + z^2> over the solid, estimated from 1.2M uniform points
    p = _capsule_points(2_000_000, np.random.default_rng(7))
    m = 3.0
    mc = m * np.array([np.mean(p[:, 1] ** 2 + p[:, 2] ** 2), np.mean(p[:, 0] ** 2 + p[:, 2] ** 2), np.mean(p[:, 0] ** 2 + p[:, 1] ** 2)])
    closed = principal_inertia("capsule", m, {"radius": R, "height": H})
    np.testing.assert_allclose(closed, mc, rtol=4e-3)
    # limits: no cylinder -> a solid sphere; the sphere's 2/5 m r^2
    np.testing.assert_allclose(principal_inertia("capsule", m, {"radius": R, "height": 1e-12}), 0.4 * m * R * R, rtol=1e-9)


class _Obj:
    shape, radius, height = "capsule", R, H


def test_bound_volume_and_tessellation() -> None:
    entry = shape_geometry("capsule")
    meas = entry.measure(_Obj(), np.ones(3), None)
    assert meas.bound == pytest.approx(H / 2 + R)
    assert meas.volume == pytest.approx(math.pi * R * R * H + 4 / 3 * math.pi * R**3)
    verts, tris = tessellate(_Obj(), 32)
    # every vertex on the surface: at distance R from the axis segment
    y = np.clip(verts[:, 1], -H / 2, H / 2)
    np.testing.assert_allclose(np.linalg.norm(verts - np.column_stack((0 * y, y, 0 * y)), axis=1), R, atol=1e-12)
    # closed and wound outward: the signed volume is positive and close to the solid's
    t = verts[tris]
    signed = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0
    assert signed == pytest.approx(meas.volume, rel=1e-2)
    # scale: radius by the larger of x and z, the cylinder's length by y
    scaled = entry.measure(_Obj(), np.array([2.0, 3.0, 1.0]), None)
    assert scaled.dims == {"radius": 2 * R, "height": 3 * H}


def _capsule(name: str, **extra: object) -> dict:
    return {"name": name, "shape": "capsule", "radius": R, "height": H, **extra}


def test_ball_lands_on_a_static_capsule(tmp_path: Path) -> None:
    # a capsule lying along x (rotated about z), top at y = 2 R; a ball falls onto its
    # cylindrical part and comes to rest on it, never inside. The capsule is turned about
    # its axis by half a facet of its tessellation (32 around), so a facet, not a ridge,
    # is on top: the mesh collider tests faces, and a ball on a tilted facet rolls off
    lying = _capsule("log", collider={"restitution": 0.0, "friction": 0.5}, transform={"translate": [0, R, 0], "rotate": {"euler": [0, 180 / 32, 90]}})
    sim = run(tmp_path, [lying, ball("b", 2.0, radius=0.1, x=0.3, restitution=0.0)], 1.5, {"integrator": "semi-implicit-euler"})
    y = sim.bodies.x[:, 0, 1]
    rest = 2 * R + 0.1
    sag = R * (1 - math.cos(math.pi / 32))  # the tessellation's facets lie inside the round surface
    assert y.min() >= rest - sag - 1e-6
    assert y[-1] == pytest.approx(rest, abs=sag + 1e-3)
    assert len(sim.bodies.impacts) >= 1 and set(sim.bodies.impacts[:, 3]) == {0.0}  # hit the capsule (collider 0)


def test_capsule_body_spins_with_its_inertia_and_rests_on_its_bound(tmp_path: Path) -> None:
    m, w = 2.0, 90.0  # kg, degrees/s about x
    spinning = _capsule("pill", transform={"translate": [0, 5, 0]}, motion={"type": "dynamics", "mass": m, "angular_velocity": [w, 0, 0]})
    sim = run(tmp_path, [spinning], 0.1, {"gravity": [0, 0, 0], "integrator": "rk4"})
    expected = 0.5 * principal_inertia("capsule", m, {"radius": R, "height": H})[0] * math.radians(w) ** 2
    assert sim.bodies.kinetic[0] == pytest.approx(expected, rel=1e-12)
    # falling onto the ground it collides as its bounding sphere (geometry.py: no contact form)
    dropped = _capsule("drop", transform={"translate": [0, 3, 0]}, motion={"type": "dynamics", "restitution": 0.0})
    sim = run(tmp_path, [floor(restitution=0.0), dropped], 2.0, name="drop")
    assert sim.bodies.x[-1, 0, 1] == pytest.approx(H / 2 + R, abs=1e-6)


def test_capsule_deforms_and_blocks_a_planned_grid(tmp_path: Path) -> None:
    from motion.pipeline.motion.deform import bind_mesh
    from motion.pipeline.motion.plan import grid_from_scene

    path = write_scene(tmp_path, [_capsule("post", transform={"translate": [2, 1, 0]})])
    loaded = load_scene(path)
    verts, _ = bind_mesh(loaded, loaded.scene.objects[0], 8)
    assert verts.shape == (2 * 9 * 17, 3)
    grid = grid_from_scene(loaded, "", 0.1, (0.0, -1.0), (4.0, 2.0), (0.5, 1.5))
    # cells whose centre is within the capsule's radius of (2, 0) are walls, far ones free
    x = 0.0 + (np.arange(grid.wall.shape[1]) + 0.5) * 0.1
    z = -1.0 + (np.arange(grid.wall.shape[0]) + 0.5) * 0.1
    d = np.hypot(x[None, :] - 2, z[:, None])
    assert grid.wall[d < R - 0.1].all() and not grid.wall[d > R + 0.1].any()


def test_capsule_renders_with_round_caps(tmp_path: Path) -> None:
    # an emitting capsule on black, seen by an orthographic camera along +z: bright
    # inside its silhouette (a 1 x 2 m stadium), dark outside, the corners of its bounding
    # rectangle dark (a cylinder of the same length would fill them)
    W = 40
    text = f"""
timeline: {{fps: 24, first: 0, last: 0}}
camera: {{type: orthographic, position: [0, 0, -5], look_at: [0, 0, 0], ortho_width: 4}}
materials: [{{name: black, type: diffuse, color: 0.0}}]
objects:
  - {{name: pill, shape: capsule, radius: {R}, height: {H}, material: black, emission: {{radiance: 1.0}}}}
render: {{resolution: [{W}, {W}], spp: 4, filter: box, max_depth: 2, motion_blur: "off"}}
"""
    (img,), _, _ = render(load(tmp_path, text), [0])
    lum = img[..., 0]
    x = column_x(W, 4.0)[None, :]
    y = column_x(W, 4.0)[:, None]  # rows fall from top (+y) to bottom
    # distance from each pixel centre to the capsule's outline in the image plane
    d = np.hypot(x, y - np.clip(y, -H / 2, H / 2)) - R
    pitch = 4.0 / W
    assert (lum[d < -pitch] > 0.9).all()
    assert (lum[d > pitch] < 0.05).all()
    corner = (np.abs(x) < R) & (np.abs(y) < H / 2 + R) & (d > pitch)  # in the bounding rectangle, off the caps
    assert corner.any() and (lum[corner] < 0.05).all()
