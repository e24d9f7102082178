"""The expression language: values, vectorisation, and every unsafe construct rejected."""

from __future__ import annotations

import math

import numpy as np
import pytest

from motion.pipeline.errors import MotionError
from motion.pipeline.expr import MAX_LENGTH, ExpressionError, parse_expression


def ev(text: str, **values: object) -> np.ndarray:
    return parse_expression(text, tuple(values) or ("t",)).evaluate(values or {"t": 0.0})


@pytest.mark.parametrize(
    ("text", "t", "expected"),
    [
        ("1 + 2 * 3", 0.0, 7.0),
        ("2 ** 3 ** 2", 0.0, 512.0),  # right-associative
        ("2 ^ 3 + 1", 0.0, 9.0),  # ^ is power with the precedence of **
        ("-t ** 2", 3.0, -9.0),
        ("7 % 3", 0.0, 1.0),
        ("sin(pi / 2) + cos(0)", 0.0, 2.0),
        ("tan(pi / 4)", 0.0, 1.0),
        ("exp(1) - e", 0.0, 0.0),
        ("log(e ^ 2)", 0.0, 2.0),
        ("sqrt(16) + abs(-2)", 0.0, 6.0),
        ("min(t, 1, -3) + max(t, 4)", 5.0, 2.0),
        ("clamp(t, 0, 1)", 7.0, 1.0),
        ("floor(t)", -1.5, -2.0),
        ("pow(t, 0.5)", 9.0, 3.0),
    ],
)
def test_values(text: str, t: float, expected: float) -> None:
    assert float(ev(text, t=t)) == pytest.approx(expected, abs=1e-12)


def test_vectorised_over_particle_arrays() -> None:
    expr = parse_expression("x * t + sin(y) - z", ("t", "x", "y", "z"))
    x, y, z = (np.random.default_rng(1).normal(size=(3, 1000)))
    out = expr.evaluate({"t": 2.0, "x": x, "y": y, "z": z})
    assert out.shape == (1000,) and out.dtype == np.float64
    np.testing.assert_allclose(out, x * 2.0 + np.sin(y) - z)
    # a constant still broadcasts to the shape of the bound arrays
    const = parse_expression("3", ("t", "x"))
    assert const.is_constant
    assert const.evaluate({"t": 0.0, "x": np.zeros(5)}).tolist() == [3.0] * 5
    assert parse_expression("t", ("t",))(t=np.arange(3.0)).tolist() == [0.0, 1.0, 2.0]


def test_domain_errors_give_nan_not_exceptions() -> None:
    assert math.isnan(float(ev("log(t)", t=-1.0)))


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("__import__('os')", "'__import__' is not an allowed function"),
        ("__import__('os').system('ls')", "attribute access"),
        ("t.__class__", "attribute access"),
        ("(1).__class__.__bases__", "attribute access"),
        ("(lambda: 1)()", "a lambda"),
        ("lambda t: t", "a lambda"),
        ("9 ** 9 ** 9", "exponent too large"),
        ("pow(10, 1000)", "exponent too large"),
        ("2 ^ 99", "exponent too large"),
        ("(" * 50 + "t" + ")" * 50, "nested too deeply"),
        ("-" * 200 + "t", "nested too deeply"),
        ("sin(" * 40 + "t" + ")" * 40, "nested too deeply"),
        ("+".join(["(t+t+t+t+t+t+t+t+t+t)"] * 41), "too many terms"),
        ("[t for t in t]", "a comprehension"),
        ("t[0]", "a subscript"),
        ("eval('1')", "'eval' is not an allowed function"),
        ("open('/etc/passwd')", "'open' is not an allowed function"),
        ("os", "unknown name 'os'"),
        ("'text'", "only numbers"),
        ("t if t else 1", "a conditional expression"),
        ("t < 1", "a comparison"),
        ("(t := 1)", "assignment"),
        ("sin(t, 2)", "takes 1 arguments"),
        ("max(t=1)", "keyword"),
        ("1e300", "too large"),
        ("t +", "syntax error"),
        ("", "empty"),
        ("t; import os", "syntax error"),
    ],
)
def test_rejected(text: str, fragment: str) -> None:
    with pytest.raises(ExpressionError, match=None) as info:
        parse_expression(text, ("t",))
    assert fragment in str(info.value), str(info.value)
    assert isinstance(info.value, MotionError)


def test_over_long_text_rejected_before_parsing() -> None:
    with pytest.raises(ExpressionError, match="too long"):
        parse_expression("1+" * MAX_LENGTH + "1", ("t",))


def test_unknown_variable_names_the_known_ones() -> None:
    with pytest.raises(ExpressionError, match=r"unknown name 'x' \(known: t, pi, e\)"):
        parse_expression("x + 1", ("t",))


def test_missing_binding_is_an_error() -> None:
    with pytest.raises(ExpressionError, match="no value bound for x"):
        parse_expression("x", ("t", "x")).evaluate({"t": 0.0})


def test_scene_validation_reports_bad_expression(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from motion.pipeline.errors import SceneError
    from motion.pipeline.scene import load_scene

    scene = tmp_path / "s.yaml"
    scene.write_text(
        "camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
        "objects:\n"
        "  - name: a\n"
        "    shape: sphere\n"
        "    motion: {type: procedural, channels: {translate: ['t', \"__import__('os')\", '0']}}\n"
    )
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    text = str(info.value)
    assert "objects[0].motion.channels.translate[1]" in text and "__import__" in text
