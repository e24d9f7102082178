"""Procedural generators against their closed forms; expression channels and scalars."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.errors import SceneError
from motion.pipeline.motion import evaluate
from motion.pipeline.motion.pose import quat_angle, quat_rotate
from motion.pipeline.motion.procedural import value_noise
from motion.pipeline.motion.rotation import euler_quat
from motion.pipeline.scene import load_scene

HEAD = "camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nobjects:\n"


def run(tmp_path: Path, objects: str, times, camera: str | None = None):  # type: ignore[no-untyped-def]
    path = tmp_path / "s.yaml"
    path.write_text((camera or HEAD.split("\n")[0]) + "\nobjects:\n" + objects)
    return evaluate(load_scene(path), np.asarray(times, dtype=float))


def test_ballistic_closed_form(tmp_path: Path) -> None:
    t = np.linspace(0.0, 3.0, 7)
    m = run(tmp_path, "  - {name: b, shape: sphere, motion: {type: procedural, generators: [{type: ballistic, x0: [1, 2, 3], v0: [4, 5, 6], a: [0, -9.81, 0], t0: 0.5}]}}\n", t)
    dt = t - 0.5
    expect = np.stack([1 + 4 * dt, 2 + 5 * dt - 0.5 * 9.81 * dt**2, 3 + 6 * dt], axis=1)
    np.testing.assert_allclose(m.objects["b"].translation, expect, atol=1e-12)


def test_orbit_radius_period_and_facing(tmp_path: Path) -> None:
    t = np.linspace(0.0, 2.0, 17)
    m = run(
        tmp_path,
        "  - {name: o, shape: sphere, transform: {translate: [0, 1, 0]}, motion: {type: procedural, generators: "
        "[{type: orbit, center: [1, 0, 0], axis: [0, 1, 0], radius: 2, period: 2, face_center: true}]}}\n",
        t,
    )
    p = m.objects["o"].translation - np.array([1.0, 1.0, 0.0])  # translations add to the transform's
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 2.0, atol=1e-12)
    np.testing.assert_allclose(p[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(p[0], [2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(p[4], [0, 0, -2], atol=1e-12)  # a quarter turn counter-clockwise about +Y
    np.testing.assert_allclose(p[-1], p[0], atol=1e-12)
    # face_center: the object's -X (towards the centre at t = 0) keeps pointing at the centre
    inward = quat_rotate(m.objects["o"].rotation, np.array([-1.0, 0, 0]))
    np.testing.assert_allclose(inward, -p / 2.0, atol=1e-12)


def test_turntable_and_oscillate(tmp_path: Path) -> None:
    t = np.array([0.0, 0.125, 0.25])
    m = run(
        tmp_path,
        "  - {name: s, shape: cube, transform: {rotate: {euler: [0, 0, 90]}}, motion: {type: procedural, generators: "
        "[{type: turntable, axis: [0, 1, 0], rate: 360, phase: 90}]}}\n"
        "  - {name: w, shape: cube, transform: {translate: [0, 1, 0]}, motion: {type: procedural, generators: "
        "[{type: oscillate, direction: [0, 0, 2], amplitude: 0.5, frequency: 2}, "
        "{type: oscillate, channel: scale, direction: [1, 0, 0], amplitude: 0.25, frequency: 1}]}}\n",
        t,
    )
    # turntable multiplies on the left of the transform's rotation: R_y(90 + 360 t) R_z(90)
    for k, tk in enumerate(t):
        expect = euler_quat((90 + 360 * tk, 90, 0), "YZX")  # intrinsic: R_y R_z
        assert quat_angle(m.objects["s"].rotation[k], expect) < 1e-9
    w = m.objects["w"]
    np.testing.assert_allclose(w.translation[:, 2], 0.5 * np.sin(2 * np.pi * 2 * t), atol=1e-12)
    np.testing.assert_allclose(w.translation[:, 1], 1.0)
    np.testing.assert_allclose(w.scale[:, 0], 1 + 0.25 * np.sin(2 * np.pi * t), atol=1e-12)


def test_noise_is_seeded_smooth_and_bounded() -> None:
    x = np.linspace(-5.0, 20.0, 20001)
    a, b, c = value_noise(1, 0, x), value_noise(1, 0, x), value_noise(2, 0, x)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.max(np.abs(a)) <= 1.0 and np.std(a) > 0.1
    slope = np.diff(a) / np.diff(x)
    assert np.max(np.abs(np.diff(slope))) < 0.05  # C1: slope changes by O(dx) per step, no jumps at lattice points


def test_noise_generator_amplitudes(tmp_path: Path) -> None:
    t = np.linspace(0, 10, 2001)
    m = run(tmp_path, "  - {name: cam_rig, shape: empty, motion: {type: procedural, generators: "
            "[{type: noise, seed: 7, translate_amplitude: [0.1, 0.02, 0], rotate_amplitude: [1, 0, 0]}]}}\n", t)
    tr = m.objects["cam_rig"].translation
    assert np.max(np.abs(tr[:, 0])) <= 0.1 and np.max(np.abs(tr[:, 0])) > 0.03
    np.testing.assert_allclose(tr[:, 2], 0.0)
    assert np.max(np.degrees(quat_angle(m.objects["cam_rig"].rotation, np.array([1.0, 0, 0, 0])))) <= 1.0 + 1e-9


def test_expression_channels_and_scalars(tmp_path: Path) -> None:
    t = np.array([0.0, 0.5, 1.0])
    camera = (
        "camera: {position: [0, 0, 5], look_at: [0, 0, 0], motion: {type: procedural, "
        "scalars: {fov: '40 + 10 * sin(pi * t)'}}}"
    )
    m = run(
        tmp_path,
        "  - {name: e, shape: cube, transform: {translate: [1, 0, 0]}, motion: {type: procedural, channels: "
        "{translate: ['t', 't^2', '0'], rotate: ['0', '90 * t', '0'], scale: '1 + t'}}}\n",
        t,
        camera=camera,
    )
    e = m.objects["e"]
    np.testing.assert_allclose(e.translation, [[1, 0, 0], [1.5, 0.25, 0], [2, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(e.scale[:, 2], [1, 1.5, 2])
    assert quat_angle(e.rotation[2], euler_quat((0, 90, 0))) < 1e-12
    np.testing.assert_allclose(m.camera_scalars["fov"], [40, 50, 40], atol=1e-12)


def test_non_finite_expression_is_a_located_error(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match=r"objects\[0\]\.motion\.channels\.translate\[1\].*not finite at t = -1"):
        run(tmp_path, "  - {name: e, shape: cube, motion: {type: procedural, channels: {translate: ['0', 'sqrt(t)', '0']}}}\n", [-1.0, 1.0])
