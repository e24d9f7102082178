"""Key poses: one compiled track per channel, evaluated at any times (vectorised over T).

Modes per segment (the key that starts a segment may override its channel's mode):
hold (value of the previous key), nearest (ties go to the later key), linear,
catmull-rom (cubic Hermite through every key with tangents (p[i+1] - p[i-1]) /
(t[i+1] - t[i-1]); C1), bezier (cubic Hermite with the keys' tangents or ease shorthand), hermite (glTF's
CUBICSPLINE: for vectors the same cubic as bezier; for rotations the cubic Hermite of the
quaternion's four components with the keys' 4-component tangents, then normalised).
End conditions and extrapolation (hold / linear / cycle) are in docs/motion.md.

Rotations interpolate on the sphere: slerp for linear, a cumulative cubic spherical Bezier
(Kim, Kim & Shin 1995) for catmull-rom and bezier, whose angular velocity at each key is
the spherical analogue of the Catmull-Rom tangent, so the rotation is C1 as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import RotationValueError, TrackError
from ..scene.motion_schema import Channel, Key
from .pose import quat_conj, quat_exp, quat_log, quat_mul, quat_normalize, quat_rotate
from .rotation import key_axis, key_quat, segment_rotvecs, unwrap_near

HOLD, NEAREST, LINEAR, CATMULL_ROM, BEZIER, HERMITE = range(6)
MODES = {"hold": HOLD, "nearest": NEAREST, "linear": LINEAR, "catmull-rom": CATMULL_ROM, "bezier": BEZIER, "hermite": HERMITE}


def _hermite(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    u2, u3 = u * u, u * u * u
    return 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u, -2 * u3 + 3 * u2, u3 - u2


@dataclass(frozen=True)
class _Frame:
    """Where each query time falls: the mapped time, its segment and fraction, and masks."""

    t: np.ndarray  # mapped query times (after cycling), [T]
    seg: np.ndarray  # segment index, [T]
    u: np.ndarray  # fraction in the segment, [T, 1]
    before: np.ndarray  # t < first key (hold / linear extrapolation)
    after: np.ndarray  # t >= last key


def _locate(times: np.ndarray, extrapolation: str, t: np.ndarray) -> _Frame:
    t0, tn = times[0], times[-1]
    span = tn - t0
    if extrapolation == "cycle" and span > 0:
        # wrap into [t0, tn): a cycle of period span repeats forever both ways
        t = t0 + np.mod(t - t0, span)
    seg = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    h = times[seg + 1] - times[seg]
    u = np.clip((t - times[seg]) / h, 0.0, 1.0)[:, None]
    return _Frame(t, seg, u, t < t0, t >= tn)


def _key_vector(key: Key, dim: int, field: str) -> np.ndarray | None:
    value = getattr(key, field)
    if value is None:
        return None
    arr = np.asarray(value, dtype=np.float64)
    return np.broadcast_to(arr, (dim,)).copy() if arr.ndim == 0 else arr


@dataclass(frozen=True)
class VectorTrack:
    """A compiled scalar or vector channel (translate, scale, fov, intensity ...)."""

    times: np.ndarray  # [n] seconds
    values: np.ndarray  # [n, D]
    modes: np.ndarray  # [n - 1] segment modes
    tan_in: np.ndarray  # [n, D] per second, for the segment ending at the key
    tan_out: np.ndarray  # [n, D] per second, for the segment starting at the key
    extrapolation: str

    @classmethod
    def compile(cls, channel: Channel, mode: str, extrapolation: str, seconds: float, dim: int) -> "VectorTrack":
        """Keys -> arrays. `seconds` is seconds per time unit (1 / fps for frames)."""
        keys = channel.keys
        n = len(keys)
        times = np.array([k.time for k in keys], dtype=np.float64) * seconds
        values = np.empty((n, dim))
        for i, k in enumerate(keys):
            v = _key_vector(k, dim, "value")
            if v is None or v.shape != (dim,):
                raise TrackError(("keys", i, "value"), f"expected {'one number' if dim == 1 else f'{dim} numbers'}")
            values[i] = v
        base = MODES[channel.interpolation or mode]
        modes = np.array([MODES[k.interpolation] if k.interpolation else base for k in keys[:-1]], dtype=np.int8)
        extrap = channel.extrapolation or extrapolation
        cr = _catmull_rom_tangents(times, values, extrap == "cycle")
        tan_in, tan_out = cr.copy(), cr.copy()
        for i, k in enumerate(keys):
            for field, target, eased in (("tangent_in", tan_in, ("in", "in-out")), ("tangent_out", tan_out, ("out", "in-out"))):
                given = _key_vector(k, dim, field)
                if given is not None:
                    if given.shape != (dim,):
                        raise TrackError(("keys", i, field), f"expected {'one number' if dim == 1 else f'{dim} numbers'}")
                    target[i] = given
                elif k.ease in eased:
                    target[i] = 0.0
        # catmull-rom segments ignore bezier tangents: keep the spline's own at both ends
        for i in np.flatnonzero(modes == CATMULL_ROM):
            tan_out[i], tan_in[i + 1] = cr[i], cr[i + 1]
        return cls(times, values, modes, tan_in, tan_out, extrap)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Values at times t [T] -> [T, D]."""
        t = np.asarray(t, dtype=np.float64)
        if len(self.times) == 1:
            return np.broadcast_to(self.values[0], (t.shape[0], self.values.shape[1])).copy()
        f = _locate(self.times, self.extrapolation, t)
        p0, p1 = self.values[f.seg], self.values[f.seg + 1]
        h = (self.times[f.seg + 1] - self.times[f.seg])[:, None]
        mode = self.modes[f.seg][:, None]
        h00, h10, h01, h11 = _hermite(f.u)
        cubic = h00 * p0 + h10 * h * self.tan_out[f.seg] + h01 * p1 + h11 * h * self.tan_in[f.seg + 1]
        out = np.where(
            mode >= CATMULL_ROM,
            cubic,
            np.where(mode == LINEAR, p0 + f.u * (p1 - p0), np.where((mode == NEAREST) & (f.u >= 0.5), p1, p0)),
        )
        out[f.after] = self.values[-1]
        if self.extrapolation == "hold":
            out[f.before] = self.values[0]
        elif self.extrapolation == "linear":
            # continue along the interpolant's own slope at the end keys
            out[f.before] = self.values[0] + (f.t[f.before] - self.times[0])[:, None] * self._slope(0)
            out[f.after] = self.values[-1] + (f.t[f.after] - self.times[-1])[:, None] * self._slope(-1)
        return out

    def _slope(self, end: int) -> np.ndarray:
        seg = 0 if end == 0 else len(self.modes) - 1
        mode = self.modes[seg]
        if mode in (HOLD, NEAREST):
            return np.zeros(self.values.shape[1])
        if mode == LINEAR:
            return (self.values[seg + 1] - self.values[seg]) / (self.times[seg + 1] - self.times[seg])
        return self.tan_out[0] if end == 0 else self.tan_in[-1]


def _catmull_rom_tangents(times: np.ndarray, values: np.ndarray, cycle: bool) -> np.ndarray:
    """m_i = (p[i+1] - p[i-1]) / (t[i+1] - t[i-1]); ends: the chord slope, or for a cycle
    the neighbours across the wrap (key n-2 before key 0, key 1 after key n-1)."""
    n = len(times)
    m = np.zeros_like(values)
    if n < 2:
        return m
    m[1:-1] = (values[2:] - values[:-2]) / (times[2:] - times[:-2])[:, None]
    if cycle:
        span = times[-1] - times[0]
        m[0] = m[-1] = (values[1] - values[-2]) / (times[1] - (times[-2] - span))
    else:
        m[0] = (values[1] - values[0]) / (times[1] - times[0])
        m[-1] = (values[-1] - values[-2]) / (times[-1] - times[-2])
    return m


@dataclass(frozen=True)
class RotationTrack:
    """A compiled rotate channel: unit quaternions on the sphere."""

    times: np.ndarray  # [n]
    quats: np.ndarray  # [n, 4]
    modes: np.ndarray  # [n - 1]
    arcs: np.ndarray  # [n - 1, 3] body-frame rotation vectors q[i+1] = q[i] exp(arc[i])
    controls: np.ndarray  # [n - 1, 3, 3] cumulative Bezier rotation vectors w1, w2, w3
    omega_start: np.ndarray  # [3] body-frame angular velocity leaving the first key (rad/s)
    omega_end: np.ndarray  # [3] arriving at the last key
    extrapolation: str
    hermite: tuple[np.ndarray, np.ndarray] | None = None  # [n, 4] dq/dt in, out (hermite segments)

    @classmethod
    def compile(cls, channel: Channel, mode: str, extrapolation: str, seconds: float) -> "RotationTrack":
        """The track of a `rotate` channel: keys as unit quaternions, per-segment modes, the
        angular velocities of its splines; `seconds` converts key times to seconds. TrackError
        (located below the channel) for keys that cannot be compiled."""
        keys = channel.keys
        n = len(keys)
        times = np.array([k.time for k in keys], dtype=np.float64) * seconds
        quats = np.empty((n, 4))
        for i, k in enumerate(keys):
            try:
                quats[i] = key_quat(k)
            except (RotationValueError, ValueError) as exc:  # ValueError: scipy's, for a malformed value
                raise TrackError(("keys", i), str(exc)) from None
        base = MODES[channel.interpolation or mode]
        modes = np.array([MODES[k.interpolation] if k.interpolation else base for k in keys[:-1]], dtype=np.int8)
        extrap = channel.extrapolation or extrapolation
        if n == 1:
            z = np.zeros((0, 3))
            return cls(times, quats, modes, z, np.zeros((0, 3, 3)), np.zeros(3), np.zeros(3), extrap)
        turns = np.array([k.turns for k in keys])
        try:
            arcs = segment_rotvecs(quats, turns, [key_axis(k) for k in keys])
        except (RotationValueError, ValueError) as exc:
            raise TrackError(("keys",), str(exc)) from None
        h = np.diff(times)
        # body-frame angular velocity at each key (rad/s): the Catmull-Rom tangent on the
        # sphere; arc[i-1] has the same axis seen from key i-1 or key i.
        omega = np.zeros((n, 3))
        omega[1:-1] = (arcs[:-1] + arcs[1:]) / (times[2:] - times[:-2])[:, None]
        if extrap == "cycle":
            omega[0] = omega[-1] = (arcs[-1] + arcs[0]) / (h[-1] + h[0])
        else:
            omega[0], omega[-1] = arcs[0] / h[0], arcs[-1] / h[-1]
        w_in, w_out = omega.copy(), omega.copy()
        for i, k in enumerate(keys):
            for field, target, eased in (("tangent_in", w_in, ("in", "in-out")), ("tangent_out", w_out, ("out", "in-out"))):
                given = getattr(k, field)
                if given is not None and isinstance(given, tuple) and len(given) == 4:
                    # glTF gives both tangents on every key, the unused end ones too
                    if not ((i > 0 and modes[i - 1] == HERMITE) or (i < n - 1 and modes[i] == HERMITE)):
                        raise TrackError(("keys", i, field), "four numbers (a quaternion derivative) are a tangent of hermite segments only")
                    continue  # read by _quaternion_tangents below
                if given is not None:
                    if not isinstance(given, tuple):
                        raise TrackError(("keys", i, field), "a rotation tangent is an angular velocity [x, y, z] in degrees/s")
                    # given in the parent frame; the spline works in the key's body frame
                    target[i] = quat_rotate(quat_conj(quats[i]), np.radians(np.asarray(given)))
                elif k.ease in eased:
                    target[i] = 0.0
        for i in np.flatnonzero(modes == CATMULL_ROM):
            w_out[i], w_in[i + 1] = omega[i], omega[i + 1]
        # cubic spherical Bezier controls: q1 = q0 exp(w1), q2 = q3 exp(-w3), w1 = omega_out h / 3
        w1 = w_out[:-1] * (h / 3.0)[:, None]
        w3 = w_in[1:] * (h / 3.0)[:, None]
        q1 = quat_mul(quats[:-1], quat_exp(w1))
        q2 = quat_mul(quats[1:], quat_exp(-w3))
        w2 = unwrap_near(quat_log(quat_mul(quat_conj(q1), q2)), arcs - w1 - w3)
        controls = np.stack((w1, w2, w3), axis=1)
        start = {HOLD: np.zeros(3), NEAREST: np.zeros(3), LINEAR: arcs[0] / h[0]}.get(int(modes[0]), w_out[0])
        end = {HOLD: np.zeros(3), NEAREST: np.zeros(3), LINEAR: arcs[-1] / h[-1]}.get(int(modes[-1]), w_in[-1])
        hermite = None
        if (modes == HERMITE).any():
            hermite = _quaternion_tangents(keys, modes)
            # the end slopes of a hermite segment: the body-frame angular velocity 2 q* q'
            if modes[0] == HERMITE:
                start = 2.0 * quat_mul(quat_conj(quats[0]), hermite[1][0])[1:]
            if modes[-1] == HERMITE:
                end = 2.0 * quat_mul(quat_conj(quats[-1]), hermite[0][-1])[1:]
        return cls(times, quats, modes, arcs, controls, start, end, extrap, hermite)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Unit quaternions at times t [T] -> [T, 4]."""
        t = np.asarray(t, dtype=np.float64)
        if len(self.times) == 1:
            return np.broadcast_to(self.quats[0], (t.shape[0], 4)).copy()
        f = _locate(self.times, self.extrapolation, t)
        q0 = self.quats[f.seg]
        mode = self.modes[f.seg][:, None]
        u = f.u
        # slerp: q0 exp(u w), constant angular velocity |w| / h along the segment
        slerp = quat_mul(q0, quat_exp(u * self.arcs[f.seg]))
        # cumulative Bernstein basis of the cubic Bezier: b1 = 1-(1-u)^3, b2 = 3u^2-2u^3, b3 = u^3
        c = self.controls[f.seg]
        b1, b2, b3 = 1.0 - (1.0 - u) ** 3, 3 * u * u - 2 * u**3, u**3
        cubic = quat_mul(quat_mul(quat_mul(q0, quat_exp(b1 * c[:, 0])), quat_exp(b2 * c[:, 1])), quat_exp(b3 * c[:, 2]))
        held = np.where((mode == NEAREST) & (u >= 0.5), self.quats[f.seg + 1], q0)
        out = np.where(mode >= CATMULL_ROM, cubic, np.where(mode == LINEAR, slerp, held))
        if self.hermite is not None:
            # glTF CUBICSPLINE: the Hermite cubic of the components, normalised below
            h00, h10, h01, h11 = _hermite(u)
            h = (self.times[f.seg + 1] - self.times[f.seg])[:, None]
            q_in, q_out = self.hermite
            herm = h00 * q0 + h10 * h * q_out[f.seg] + h01 * self.quats[f.seg + 1] + h11 * h * q_in[f.seg + 1]
            out = np.where(mode == HERMITE, herm, out)
        out[f.after] = self.quats[-1]
        if self.extrapolation == "hold":
            out[f.before] = self.quats[0]
        elif self.extrapolation == "linear":
            dt0 = (f.t[f.before] - self.times[0])[:, None]
            dtn = (f.t[f.after] - self.times[-1])[:, None]
            out[f.before] = quat_mul(self.quats[0], quat_exp(dt0 * self.omega_start))
            out[f.after] = quat_mul(self.quats[-1], quat_exp(dtn * self.omega_end))
        return quat_normalize(out)


def _quaternion_tangents(keys: list[Key], modes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-key quaternion-component tangents (dq/dt, per second) of hermite segments:
    a key's `tangent_in` / `tangent_out` given as four numbers (w, x, y, z); zero if absent."""
    n = len(keys)
    q_in, q_out = np.zeros((n, 4)), np.zeros((n, 4))
    for i, k in enumerate(keys):
        for field, target, used in (("tangent_in", q_in, i > 0 and modes[i - 1] == HERMITE), ("tangent_out", q_out, i < n - 1 and modes[i] == HERMITE)):
            given = getattr(k, field)
            if given is None or not used:
                continue
            if not isinstance(given, tuple) or len(given) != 4:
                raise TrackError(("keys", i, field), "a hermite rotation tangent is a quaternion derivative [w, x, y, z] per second")
            target[i] = given
    return q_in, q_out
