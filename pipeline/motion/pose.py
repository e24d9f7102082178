"""Poses over time and the quaternion arithmetic under them (numpy, vectorised over T).

A `Pose` holds world_from_object = T(translation) * R(rotation) * S(scale) at T times.
Quaternions are (w, x, y, z) arrays of shape [..., 4]; scipy's `Rotation` is scalar-last,
so conversions pass `scalar_first=True` at the boundary (rotation.py).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Pose(NamedTuple):
    """world_from_object at T times: translation [T, 3], rotation [T, 4] (w, x, y, z), scale [T, 3]."""

    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray

    @property
    def count(self) -> int:
        """Number of time samples."""
        return int(self.translation.shape[0])

    def matrices(self) -> np.ndarray:
        """[T, 4, 4] homogeneous matrices T * R * S."""
        rs = quat_to_matrix(self.rotation) * self.scale[:, None, :]
        out = np.zeros((self.count, 4, 4))
        out[:, :3, :3] = rs
        out[:, :3, 3] = self.translation
        out[:, 3, 3] = 1.0
        return out

    def take(self, index: np.ndarray | slice | int) -> "Pose":
        """The pose at a subset of the time samples (keeps the leading axis for ints)."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1)
        return Pose(self.translation[index], self.rotation[index], self.scale[index])

    def transform_points(self, points: np.ndarray) -> np.ndarray:
        """Map object-space points [V, 3] to world space at every time: [T, V, 3]."""
        scaled = points[None, :, :] * self.scale[:, None, :]
        return quat_rotate(self.rotation[:, None, :], scaled) + self.translation[:, None, :]


def constant_pose(count: int, translation=(0.0, 0.0, 0.0), rotation=(1.0, 0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)) -> Pose:  # type: ignore[no-untyped-def]
    """A pose that does not change over `count` samples."""
    return Pose(
        np.broadcast_to(np.asarray(translation, dtype=np.float64), (count, 3)).copy(),
        np.broadcast_to(np.asarray(rotation, dtype=np.float64), (count, 4)).copy(),
        np.broadcast_to(np.asarray(scale, dtype=np.float64), (count, 3)).copy(),
    )


def compose(world_from_parent: Pose, parent_from_child: Pose) -> Pose:
    """world_from_child = world_from_parent * parent_from_child.

    Translation and rotation compose exactly; scale composes component-wise, which is
    exact for a uniform parent scale and otherwise drops the shear a non-uniform parent
    scale would put on a rotated child (docs/motion.md, "Parent frames")."""
    p, c = world_from_parent, parent_from_child
    # T_p R_p S_p (T_c x) = t_p + R_p (s_p * t_c): the child's origin in world space.
    translation = p.translation + quat_rotate(p.rotation, p.scale * c.translation)
    rotation = quat_normalize(quat_mul(p.rotation, c.rotation))
    return Pose(translation, rotation, p.scale * c.scale)


# --- quaternions (w, x, y, z) -------------------------------------------------------------


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (broadcasting over leading axes)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b, np.float64))
    # written component by component into one array: small batches (a few rigid bodies per
    # simulation step) are dominated by the cost of each numpy call, not the arithmetic
    out[..., 0] = aw * bw - ax * bx - ay * by - az * bz
    out[..., 1] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 2] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate = inverse for unit quaternions."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions; a zero quaternion becomes the identity."""
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), 0.0)
    out[..., 0] = np.where(norm[..., 0] > 0, out[..., 0], 1.0)
    return out


# Below this sin(theta) a slerp is a lerp (then normalised): one scheme, two precisions. The
# host's float64 resolves sin(theta) to 1e-6; the render kernel's float32 (render/poses.py
# `slerp`, the same formula in drjit) loses sin((1 - f) theta) / sin(theta) to rounding
# below about 1e-4.
SLERP_LINEAR_BELOW = {"float64": 1e-6, "float32": 1e-4}


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation [..., 4] with the shortest-path flip; s in [0, 1]."""
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    s = np.asarray(s)[..., None]
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < SLERP_LINEAR_BELOW["float64"]
    safe = np.where(small, 1.0, sin_theta)
    # (sin((1-s) theta) q0 + sin(s theta) q1) / sin(theta); lerp where theta ~ 0
    a = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    b = np.where(small, s, np.sin(s * theta) / safe)
    return quat_normalize(a * q0 + b * q1)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v [..., 3] by unit quaternions q [..., 4]."""
    w = q[..., :1]
    u = q[..., 1:]
    # q v q* = v + 2 w (u x v) + 2 u x (u x v)  (expanded sandwich product)
    uv = np.cross(u, v)
    return v + 2.0 * (w * uv + np.cross(u, uv))


def quat_exp(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation vector (axis * angle, radians); any angle."""
    theta = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    # sin(theta/2)/theta = 0.5 * sinc(theta / 2pi) with numpy's normalised sinc: no 0/0.
    k = 0.5 * np.sinc(theta / (2.0 * np.pi))
    return np.concatenate((np.cos(theta / 2.0), k * rotvec), axis=-1)


def quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vector of the shortest arc (angle in [0, pi]) of a unit quaternion."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    w = np.clip(q[..., :1], -1.0, 1.0)
    v = q[..., 1:]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    theta = 2.0 * np.arctan2(n, w)
    # theta / n -> 2 / w as n -> 0 (theta ~ 2 n / w).
    scale = np.where(n > 1e-12, theta / np.where(n > 1e-12, n, 1.0), 2.0 / np.maximum(w, 1e-12))
    return v * scale


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """[..., 4] unit quaternions -> [..., 3, 3] rotation matrices."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3), dtype=np.result_type(q, np.float64))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (radians, [0, pi]) of the rotation taking a to b."""
    rel = quat_mul(quat_conj(a), b)
    # 2 atan2(|v|, |w|) keeps full precision near 0, where 2 acos(|w|) loses half the digits
    return 2.0 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))
