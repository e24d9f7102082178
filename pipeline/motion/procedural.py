"""Procedural motion: closed-form generators and expression channels, vectorised over T.

Each generator yields a `Layer` (translation offset [T, 3], rotation [T, 4], scale factor
[T, 3]); layers compose on top of the object's `transform:` in order: translations add,
rotations multiply on the left, scale factors multiply. Formulas in docs/motion.md.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..errors import ExpressionValueError, RotationValueError
from ..expr import parse_expression
from ..scene.motion_schema import Ballistic, Generator, Noise, Orbit, Oscillate, ProceduralMotion, Turntable
from .pose import quat_exp, quat_mul
from .rotation import euler_quat


class Layer(NamedTuple):
    """One generator's contribution to a local transform, at T times."""

    translation: np.ndarray  # [T, 3] added
    rotation: np.ndarray  # [T, 4] multiplied on the left
    scale: np.ndarray  # [T, 3] multiplied


def _unit(v) -> np.ndarray:  # type: ignore[no-untyped-def]
    a = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(a)
    if n < 1e-12:
        raise RotationValueError("axis/direction must not be the zero vector")
    return a / n


def _identity(count: int) -> Layer:
    rot = np.zeros((count, 4))
    rot[:, 0] = 1.0
    return Layer(np.zeros((count, 3)), rot, np.ones((count, 3)))


def _spin(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternions of rotations by angle [T] (radians) about a unit axis."""
    return quat_exp(angle[:, None] * axis[None, :])


def ballistic(g: Ballistic, t: np.ndarray) -> Layer:
    """x(t) = x0 + v0 (t - t0) + a (t - t0)^2 / 2."""
    out = _identity(len(t))
    dt = (t - g.t0)[:, None]
    # x(t) = x0 + v0 dt + a dt^2 / 2
    out.translation[:] = np.asarray(g.x0) + np.asarray(g.v0) * dt + 0.5 * np.asarray(g.a) * dt * dt
    return out


def orbit_basis(axis: np.ndarray) -> np.ndarray:
    """The orbit's start direction: world +X projected onto the orbit plane (+Z if the axis is X)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = ref - np.dot(ref, axis) * axis
    return e1 / np.linalg.norm(e1)


def orbit(g: Orbit, t: np.ndarray) -> Layer:
    """A circle of `radius` about `center` in the plane normal to `axis` (period, phase);
    with face_center the object turns with the orbit, keeping one side to the centre."""
    out = _identity(len(t))
    axis = _unit(g.axis)
    # theta = phase + 2 pi t / period, counter-clockwise about the axis (right hand)
    theta = np.radians(g.phase) + 2.0 * np.pi * t / g.period
    spin = _spin(axis, theta)
    e1 = orbit_basis(axis)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    # R(axis, theta) e1 = cos(theta) e1 + sin(theta) (axis x e1)   (e1 is perpendicular to axis)
    out.translation[:] = np.asarray(g.center) + g.radius * (c * e1 + s * np.cross(axis, e1))
    if g.face_center:
        out.rotation[:] = spin
    return out


def oscillate(g: Oscillate, t: np.ndarray) -> Layer:
    """A sine wave on translate (along direction), rotate (about direction, degrees) or scale (1 + wave, weighted per axis)."""
    out = _identity(len(t))
    wave = g.amplitude * np.sin(2.0 * np.pi * g.frequency * t + np.radians(g.phase))
    if g.channel == "translate":
        out.translation[:] = wave[:, None] * _unit(g.direction)
    elif g.channel == "rotate":
        out.rotation[:] = _spin(_unit(g.direction), np.radians(wave))
    else:  # scale: factor 1 + wave * direction component (direction weights the axes)
        out.scale[:] = 1.0 + wave[:, None] * np.asarray(g.direction)
    return out


def turntable(g: Turntable, t: np.ndarray) -> Layer:
    """A steady spin about `axis`: phase + rate * t degrees."""
    out = _identity(len(t))
    out.rotation[:] = _spin(_unit(g.axis), np.radians(g.phase + g.rate * t))
    return out


def _lattice(seed: int, stream: int, cells: np.ndarray) -> np.ndarray:
    """Deterministic values in [-1, 1] at integer lattice points (splitmix64 hash)."""
    with np.errstate(over="ignore"):
        x = cells.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        x ^= np.uint64((seed * 0x632BE59BD9B4E019 + stream * 0x8CB92BA72F3D8DD7) & 0xFFFFFFFFFFFFFFFF)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x ^= x >> np.uint64(31)
    return (x >> np.uint64(11)).astype(np.float64) / float(1 << 53) * 2.0 - 1.0


def value_noise(seed: int, stream: int, x: np.ndarray) -> np.ndarray:
    """Smooth 1D value noise in [-1, 1]: lattice values blended with the quintic fade
    6u^5 - 15u^4 + 10u^3 (C2 across cells); two octaves (1 and 1/2 amplitude), normalised."""
    total = np.zeros_like(x)
    for octave, amp in ((0, 1.0), (1, 0.5)):
        xs = x * (2**octave)
        cell = np.floor(xs)
        u = xs - cell
        fade = u * u * u * (u * (6.0 * u - 15.0) + 10.0)
        i = cell.astype(np.int64)
        a = _lattice(seed, 2 * stream + octave, i)
        b = _lattice(seed, 2 * stream + octave, i + 1)
        total += amp * (a + fade * (b - a))
    return total / 1.5


def noise(g: Noise, t: np.ndarray) -> Layer:
    """Smooth deterministic jitter (seeded value noise) of translation and rotation."""
    out = _identity(len(t))
    x = t * g.frequency
    for k in range(3):
        out.translation[:, k] = g.translate_amplitude[k] * value_noise(g.seed, k, x)
    angles = np.stack([g.rotate_amplitude[k] * value_noise(g.seed, 3 + k, x) for k in range(3)], axis=-1)
    out.rotation[:] = euler_quat(angles, "xyz")
    return out


GENERATORS: dict[str, Callable[..., Layer]] = {
    "ballistic": ballistic,
    "orbit": orbit,
    "oscillate": oscillate,
    "turntable": turntable,
    "noise": noise,
}


def generator_layer(g: Generator, t: np.ndarray) -> Layer:
    """Dispatch on the generator's `type`."""
    return GENERATORS[g.type](g, t)


def _expr(text: str, t: np.ndarray, loc: tuple[str | int, ...]) -> np.ndarray:
    value = parse_expression(text, ("t",)).evaluate({"t": t})
    bad = ~np.isfinite(value)
    if bad.any():
        raise ExpressionValueError(loc, f"expression {text!r} is not finite at t = {float(t[np.argmax(bad)]):g} s")
    return value


def procedural_layers(motion: ProceduralMotion, t: np.ndarray) -> list[Layer]:
    """The generators' layers in order, then the expression channels' layer."""
    layers = []
    for i, g in enumerate(motion.generators):
        try:
            layers.append(generator_layer(g, t))
        except (RotationValueError, ValueError) as exc:  # ValueError: numpy's, for a value it cannot use
            raise ExpressionValueError(("generators", i), str(exc)) from None
    ch = motion.channels
    if ch is not None:
        layer = _identity(len(t))
        if ch.translate is not None:
            for k, text in enumerate(ch.translate):
                layer.translation[:, k] = _expr(text, t, ("channels", "translate", k))
        if ch.rotate is not None:
            angles = np.stack([_expr(text, t, ("channels", "rotate", k)) for k, text in enumerate(ch.rotate)], axis=-1)
            layer.rotation[:] = euler_quat(angles, ch.order)
        if ch.scale is not None:
            if isinstance(ch.scale, str):
                layer.scale[:] = _expr(ch.scale, t, ("channels", "scale"))[:, None]
            else:
                for k, text in enumerate(ch.scale):
                    layer.scale[:, k] = _expr(text, t, ("channels", "scale", k))
        layers.append(layer)
    return layers


def procedural_scalars(motion: ProceduralMotion, t: np.ndarray) -> dict[str, np.ndarray]:
    """The scalar channels' expressions (fov, intensity ...) evaluated at t."""
    return {name: _expr(text, t, ("scalars", name)) for name, text in motion.scalars.items()}


def apply_layers(translation: np.ndarray, rotation: np.ndarray, scale: np.ndarray, layers: list[Layer]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compose layers over a base local transform (each [T, ...])."""
    for layer in layers:
        translation = translation + layer.translation
        rotation = quat_mul(layer.rotation, rotation)
        scale = scale * layer.scale
    return translation, rotation, scale
