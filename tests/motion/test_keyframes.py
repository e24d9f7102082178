"""Key poses: every interpolation mode against hand-computed values, end conditions,
extrapolation, and catmull-rom's C1 continuity checked numerically."""

from __future__ import annotations

import numpy as np
import pytest

from motion.pipeline.motion import evaluate
from motion.pipeline.motion.keyframes import VectorTrack
from motion.pipeline.scene import load_scene
from motion.pipeline.scene.motion_schema import Channel, Key


def track(points, mode="linear", extrapolation="hold", extra=None) -> VectorTrack:  # type: ignore[no-untyped-def]
    extra = extra or {}
    keys = [Key(time=t, value=v, **extra.get(i, {})) for i, (t, v) in enumerate(points)]
    return VectorTrack.compile(Channel(keys=keys), mode, extrapolation, 1.0, 1)


def at(tr: VectorTrack, *times: float) -> list[float]:
    return [round(float(v), 12) for v in tr(np.array(times))[:, 0]]


STEPS = [(0.0, 0.0), (1.0, 10.0), (2.0, 20.0)]


def test_hold_rounds_down_to_the_previous_key() -> None:
    assert at(track(STEPS, "hold"), 0.0, 0.5, 0.999, 1.0, 1.5, 2.0) == [0, 0, 0, 10, 10, 20]


def test_nearest_ties_go_to_the_later_key() -> None:
    assert at(track(STEPS, "nearest"), 0.0, 0.49, 0.5, 1.2, 1.6, 2.0) == [0, 0, 10, 10, 20, 20]


def test_linear_between_and_at_keys() -> None:
    assert at(track([(0, 0), (1, 10), (3, 0)], "linear"), 0, 0.25, 1, 2, 2.5) == [0, 2.5, 10, 5, 2.5]


CR = [(0.0, 0.0), (1.0, 1.0), (2.0, 0.0), (3.0, 1.0)]


def test_catmull_rom_hand_values() -> None:
    tr = track(CR, "catmull-rom")
    # tangents: m0 = chord 1 (end condition), m1 = (0 - 0) / 2 = 0, m2 = 0, m3 = chord 1
    # mid segment 0: h00 p0 + h10 m0 + h01 p1 + h11 m1 = 0 + 0.125 + 0.5 + 0 = 0.625
    # mid segment 1: 0.5 * 1 + 0.5 * 0 = 0.5; keys are passed through exactly
    assert at(tr, 0, 0.5, 1, 1.5, 2, 3) == [0, 0.625, 1, 0.5, 0, 1]
    # u = 0.25 in segment 0: h10 = 0.140625, h01 = 0.15625 -> 0.296875
    assert at(tr, 0.25) == [0.296875]


def _one_sided_slopes(f, t: float, eps: float = 1e-5) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Second-order one-sided differences: f'(t) = (3 f(t) - 4 f(t - e) + f(t - 2e)) / 2e + O(e^2)."""
    left = (3 * f(t) - 4 * f(t - eps) + f(t - 2 * eps)) / (2 * eps)
    right = (-3 * f(t) + 4 * f(t + eps) - f(t + 2 * eps)) / (2 * eps)
    return left, right


@pytest.mark.parametrize("times", [[0.0, 1.0, 2.0, 3.0], [0.0, 0.3, 2.0, 2.2, 5.0]])
def test_catmull_rom_is_c1_across_keys(times: list[float]) -> None:
    values = [0.0, 1.0, -2.0, 0.5, 3.0][: len(times)]
    cr = track(list(zip(times, values)), "catmull-rom")
    lin = track(list(zip(times, values)), "linear")
    f_cr = lambda t: float(cr(np.array([t]))[0, 0])  # noqa: E731
    f_lin = lambda t: float(lin(np.array([t]))[0, 0])  # noqa: E731
    for t in times[1:-1]:
        left, right = _one_sided_slopes(f_cr, t)
        assert left == pytest.approx(right, abs=1e-4)
        left, right = _one_sided_slopes(f_lin, t)  # the check does see a kink when there is one
        assert abs(left - right) > 0.1


def test_bezier_tangents_and_ease() -> None:
    tr = track([(0, 0), (1, 1)], "bezier", extra={0: {"tangent_out": 2.0}, 1: {"tangent_in": 0.0}})
    # h10 * h * m0 + h01 * p1 = 0.125 * 2 + 0.5 = 0.75
    assert at(tr, 0.5) == [0.75]
    eased = track([(0, 0), (1, 1)], "bezier", extra={0: {"ease": "in-out"}, 1: {"ease": "in-out"}})
    # zero tangents: the smoothstep 3u^2 - 2u^3
    assert at(eased, 0.25, 0.5, 0.75) == [0.15625, 0.5, 0.84375]
    # without tangents bezier keys take the catmull-rom tangents
    plain = track(CR, "bezier")
    assert at(plain, 0.5, 1.5) == at(track(CR, "catmull-rom"), 0.5, 1.5)


def test_per_key_interpolation_overrides_the_segment() -> None:
    tr = track(STEPS, "linear", extra={1: {"interpolation": "hold"}})
    assert at(tr, 0.5, 1.5) == [5.0, 10.0]


def test_extrapolation_hold_linear_cycle() -> None:
    pts = [(0, 0), (1, 10), (2, 0)]
    assert at(track(pts, "linear", "hold"), -1, 3) == [0, 0]
    assert at(track([(0, 0), (1, 2)], "linear", "linear"), -1, 3) == [-2, 6]
    # linear extrapolation of a catmull-rom track follows its end tangent (the chord)
    assert at(track([(0, 0), (1, 2), (2, 6)], "catmull-rom", "linear"), 3) == [10]
    cyc = track(pts, "linear", "cycle")
    assert at(cyc, 2.5, 4.0, -0.5, 10.25) == [5, 0, 5, 2.5]


def test_cycle_catmull_rom_is_c1_across_the_wrap() -> None:
    tr = track([(0, 0), (1, 1), (2, -1), (3, 0)], "catmull-rom", "cycle")
    f = lambda t: float(tr(np.array([t]))[0, 0])  # noqa: E731
    left, right = _one_sided_slopes(f, 3.0)
    assert left == pytest.approx(right, abs=1e-4)
    assert f(0.4) == pytest.approx(f(3.4))


def test_vector_channels_interpolate_per_component() -> None:
    keys = [Key(time=0, value=(0.0, 1.0, 2.0)), Key(time=2, value=(2.0, 1.0, -2.0))]
    tr = VectorTrack.compile(Channel(keys=keys), "linear", "hold", 1.0, 3)
    np.testing.assert_allclose(tr(np.array([1.0])), [[1.0, 1.0, 0.0]])


SCENE = """
timeline: {fps: 24, first: 0, last: 47}
camera:
  position: [0, 0, 5]
  look_at: [0, 0, 0]
  motion:
    type: keyframes
    channels:
      fov: {keys: [{time: 0, value: 30}, {time: 48, value: 60}]}
lights:
  - type: point
    position: [0, 3, 0]
    motion: {type: keyframes, channels: {intensity: {keys: [{time: 0, value: 0}, {time: 24, value: [2, 4, 6]}]}}}
objects:
  - name: box
    shape: cube
    transform: {translate: [0, 0, 1], scale: 2}
    motion:
      type: keyframes
      channels:
        translate: {keys: [{time: 0, value: [0, 0, 0]}, {time: 24, value: [1, 2, 3]}]}
        scale: {keys: [{time: 0, value: 1}, {time: 24, value: 3}]}
"""


def test_frames_time_unit_scalars_and_replacement(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "s.yaml"
    path.write_text(SCENE)
    m = evaluate(load_scene(path), np.array([0.0, 0.5, 1.0]))
    box = m.objects["box"]
    # keyed translate replaces the transform's (1 s = frame 24)
    np.testing.assert_allclose(box.translation, [[0, 0, 0], [0.5, 1, 1.5], [1, 2, 3]])
    np.testing.assert_allclose(box.scale[:, 0], [1, 2, 3])
    np.testing.assert_allclose(m.camera_scalars["fov"], [30, 37.5, 45])
    np.testing.assert_allclose(m.light_scalars["light0"]["intensity"], [[0, 0, 0], [1, 2, 3], [2, 4, 6]])


def test_wrong_value_shape_is_a_located_error(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from motion.pipeline.errors import SceneError

    path = tmp_path / "s.yaml"
    path.write_text(SCENE.replace("value: 30}", "value: [30, 1, 2]}"))
    with pytest.raises(SceneError, match=r"camera\.motion\.channels\.fov"):
        evaluate(load_scene(path), np.array([0.0]))
