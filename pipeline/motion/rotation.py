"""Rotations from the scene file's forms to unit quaternions, and rotation segments.

The conversions (Euler in any order, axis-angle, matrices) follow scipy's `Rotation`
exactly (same convention, composition order and sign; tests compare them to 1 ulp) but are
written with numpy: importing scipy.spatial (scipy.sparse and the k-d tree come with it)
would be most of a small job's start-up (docs/motion.md). Segment interpolation is written
with `quat_exp`/`quat_log` (pose.py) because scipy's `Slerp` cannot represent multi-turn
segments (`turns:`) nor the cumulative spherical Bezier we use for catmull-rom and bezier
keys (docs/motion.md, "Rotations").
"""

from __future__ import annotations

import numpy as np

from ..errors import RotationValueError
from ..scene.motion_schema import Key
from ..scene.types import AxisAngleRotation, EulerRotation, QuaternionRotation, Transform
from .pose import matrix_to_quat, quat_conj, quat_log, quat_mul, quat_normalize, quat_rotate, quat_to_matrix

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


_AXIS = {"x": 1, "y": 2, "z": 3}  # the component of a (w, x, y, z) quaternion along each axis


def euler_quat(angles_deg, order: str = "xyz") -> np.ndarray:  # type: ignore[no-untyped-def]
    """Euler angles in degrees -> (w, x, y, z); lowercase order = extrinsic (about the fixed
    axes, the first letter first), uppercase = intrinsic (about the turning axes): scipy's
    `Rotation.from_euler` convention and composition order, so the same quaternion, sign
    included (tests/motion/test_rotation.py compares every order). Written with numpy
    because importing scipy.spatial would weigh on every process (docs/motion.md)."""
    half = np.radians(np.asarray(angles_deg, dtype=np.float64)) / 2.0
    out = None
    for i, axis in enumerate(order):
        q = np.zeros(half.shape[:-1] + (4,))
        q[..., 0] = np.cos(half[..., i])
        q[..., _AXIS[axis.lower()]] = np.sin(half[..., i])
        out = q if out is None else (quat_mul(q, out) if order.islower() else quat_mul(out, q))
    return out  # type: ignore[return-value]


def matrix_quat(m: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a 3x3 rotation matrix, by the largest of its
    trace and diagonal (scipy's `Rotation.from_matrix` method and sign)."""
    m = np.asarray(m, dtype=np.float64)
    decision = (m[0, 0], m[1, 1], m[2, 2], m[0, 0] + m[1, 1] + m[2, 2])
    choice = int(np.argmax(decision))
    q = np.empty(4)  # x, y, z, w as scipy computes them
    if choice != 3:
        i, j, k = choice, (choice + 1) % 3, (choice + 2) % 3
        q[i] = 1.0 - decision[3] + 2.0 * m[i, i]
        q[j] = m[j, i] + m[i, j]
        q[k] = m[k, i] + m[i, k]
        q[3] = m[k, j] - m[j, k]
    else:
        q[0] = m[2, 1] - m[1, 2]
        q[1] = m[0, 2] - m[2, 0]
        q[2] = m[1, 0] - m[0, 1]
        q[3] = 1.0 + decision[3]
    q /= np.linalg.norm(q)
    return np.array([q[3], q[0], q[1], q[2]])


def axis_angle_quat(axis, angle_deg: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The unit quaternion (w, x, y, z) of a rotation by `angle_deg` degrees about `axis`."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    half = np.radians(angle_deg) / 2.0
    return np.concatenate(([np.cos(half)], np.sin(half) * a))


def transform_quat(rotation: EulerRotation | AxisAngleRotation | QuaternionRotation | None) -> np.ndarray:
    """The quaternion of a `transform.rotate` block (identity when absent)."""
    if rotation is None:
        return IDENTITY.copy()
    if isinstance(rotation, EulerRotation):
        return euler_quat(rotation.euler, rotation.order)
    if isinstance(rotation, AxisAngleRotation):
        return axis_angle_quat(rotation.axis, rotation.angle)
    return quat_normalize(np.asarray(rotation.quaternion, dtype=np.float64))


def parent_from_object(transform: Transform) -> np.ndarray:
    """4x4 T(translate) R(rotate) S(scale) of a scene `transform:`: the object's frame in
    its parent's (the world's, for an object without a parent)."""
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(transform_quat(transform.rotate)) * np.asarray(transform.scale, dtype=np.float64)[None, :]
    m[:3, 3] = transform.translate
    return m


def key_quat(key: Key) -> np.ndarray:
    """The quaternion of a rotate key: `value` (Euler xyz degrees), `euler` + `order`,
    `axis` + `angle`, or `quaternion` (w, x, y, z)."""
    if key.quaternion is not None:
        q = np.asarray(key.quaternion, dtype=np.float64)
        norm = np.linalg.norm(q)
        if norm < 1e-12:
            raise RotationValueError("quaternion must not be zero")
        return q / norm
    if key.axis is not None and key.angle is not None:
        if np.linalg.norm(key.axis) < 1e-12:
            raise RotationValueError("axis must not be the zero vector")
        return axis_angle_quat(key.axis, key.angle)
    if key.euler is not None:
        return euler_quat(key.euler, key.order)
    if isinstance(key.value, tuple):
        return euler_quat(key.value, "xyz")
    raise RotationValueError("a rotation key's value is Euler angles [x, y, z] in degrees")


def key_axis(key: Key) -> np.ndarray | None:
    """The spin axis a key names, for `turns` on a segment whose shortest arc is zero:
    its `axis`, or the one axis of an Euler key with a single non-zero angle."""
    if key.axis is not None:
        a = np.asarray(key.axis, dtype=np.float64)
        return a / np.linalg.norm(a)
    angles = key.euler if key.euler is not None else key.value if isinstance(key.value, tuple) else None
    if angles is None:
        return None
    order = key.order if key.euler is not None else "xyz"
    nonzero = [i for i, a in enumerate(angles) if abs(a) > 1e-12]
    if len(nonzero) != 1:
        return None
    axis = np.zeros(3)
    axis["xyz".index(order[nonzero[0]].lower())] = np.sign(angles[nonzero[0]])
    return axis


def segment_rotvecs(quats: np.ndarray, turns: np.ndarray, axes: list[np.ndarray | None]) -> np.ndarray:
    """Body-frame rotation vectors w_i of the segments, q_{i+1} = q_i exp(w_i).

    Each is the shortest arc (|w_i| <= pi) plus `turns[i+1]` whole turns about its axis;
    a zero-length arc takes the axis from key i+1 (`axes[i+1]`). Raises RotationValueError
    (with the key index) when turns are asked on a segment with no axis."""
    rel = quat_mul(quat_conj(quats[:-1]), quats[1:])
    w = quat_log(rel)
    for i in np.flatnonzero(turns[1:]):
        angle = np.linalg.norm(w[i])
        if angle > 1e-9:
            axis = w[i] / angle
        elif axes[i + 1] is not None:
            # the key's axis is in the parent frame; at a zero arc q_i = q_{i+1}, so map it into the body frame
            axis = quat_rotate(quat_conj(quat_normalize(quats[i])), np.asarray(axes[i + 1], dtype=np.float64))
        else:
            raise RotationValueError(f"keys[{i + 1}]: turns on a segment with no rotation needs an axis: give the key as axis + angle")
        w[i] = w[i] + 2.0 * np.pi * turns[i + 1] * axis
    return w


def unwrap_near(rotvec: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Among the rotation vectors of the same rotation (axis * (angle + 2 pi k)), the one
    nearest `target` (row-wise): keeps multi-turn segments whole through spline controls."""
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    tnorm = np.linalg.norm(target, axis=-1, keepdims=True)
    axis = np.where(angle > 1e-9, rotvec / np.maximum(angle, 1e-300), target / np.maximum(tnorm, 1e-300))
    along = np.sum(target * axis, axis=-1, keepdims=True)
    k = np.round((along - angle) / (2.0 * np.pi))
    return axis * (angle + 2.0 * np.pi * k)


def look_at_quat(origin, target, up) -> np.ndarray:  # type: ignore[no-untyped-def]
    """world_from_camera rotation of Mitsuba's look_at: local +Z forward, +Y up, +X left."""
    o, t, u = (np.asarray(v, dtype=np.float64) for v in (origin, target, up))
    forward = t - o
    forward /= np.linalg.norm(forward)
    left = np.cross(u, forward)
    if np.linalg.norm(left) < 1e-9:  # up parallel to the view: pick any perpendicular up
        left = np.cross(np.array([1.0, 0.0, 0.0]) if abs(forward[0]) < 0.9 else np.array([0.0, 0.0, 1.0]), forward)
    left /= np.linalg.norm(left)
    new_up = np.cross(forward, left)
    return matrix_quat(np.column_stack((left, new_up, forward)))


def direction_quat(direction) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The rotation taking local +Z to `direction` (directional lights)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    return look_at_quat(np.zeros(3), d, up)


def aim_quats(origins: np.ndarray, targets: np.ndarray, up: np.ndarray) -> np.ndarray:
    """[T, 4] `look_at_quat` at every sample: local +Z from origins [T, 3] towards targets
    [T, 3], +Y towards up ([3] or [T, 3]), +X left; an up parallel to the view picks a
    perpendicular as look_at_quat does. Every origin must differ from its target."""
    forward = targets - origins
    forward = forward / np.linalg.norm(forward, axis=-1, keepdims=True)
    left = np.cross(np.broadcast_to(up, forward.shape), forward)
    parallel = np.linalg.norm(left, axis=-1) < 1e-9
    if parallel.any():
        other = np.where((np.abs(forward[parallel, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
        left[parallel] = np.cross(other, forward[parallel])
    left = left / np.linalg.norm(left, axis=-1, keepdims=True)
    new_up = np.cross(forward, left)
    return matrix_to_quat(np.stack((left, new_up, forward), axis=-1))
