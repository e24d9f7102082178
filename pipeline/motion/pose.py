"""Poses over time and the quaternion arithmetic under them (numpy, vectorised over T).

A `Pose` holds world_from_object = T(translation) * R(rotation) * S at T times, S the
symmetric stretch: its diagonal is `scale`, its off-diagonal terms `stretch_offdiag` (None
while S is diagonal, which it is for every pose a `transform:` or a motion block makes).
Composing under a non-uniform parent scale gives a general S (the polar decomposition of
the 4x4 product, as pbrt-v4's AnimatedTransform::Decompose): exact, never dropped. Any
3x3 is a rotation times a symmetric matrix, so every finite product is held (a mirror as
one negative eigenvalue of S, as a negative `scale` is).
Quaternions are (w, x, y, z) arrays of shape [..., 4]; scipy's `Rotation` is scalar-last,
so conversions pass `scalar_first=True` at the boundary (rotation.py).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np

from ..errors import MotionError

# (row, column) of the off-diagonal terms in `stretch_offdiag`: S_xy, S_xz, S_yz
OFFDIAG = ((0, 1), (0, 2), (1, 2))
# |B - B^T| below this fraction of |B| is round-off: B is already the stretch
SYMMETRY_TOLERANCE = 1e-12


class UnrepresentablePoseError(MotionError):
    """A composed world_from_object that a rotation times a symmetric stretch cannot hold
    (it is not finite); `samples` are the time indices affected."""

    def __init__(self, message: str, samples: np.ndarray) -> None:
        super().__init__(message)
        self.samples = samples


class Pose(NamedTuple):
    """world_from_object at T times: translation [T, 3], rotation [T, 4] (w, x, y, z),
    scale [T, 3] (the stretch's diagonal) and stretch_offdiag [T, 3] (its S_xy, S_xz, S_yz)
    or None where the stretch is diagonal."""

    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    stretch_offdiag: np.ndarray | None = None

    @property
    def count(self) -> int:
        """Number of time samples."""
        return int(self.translation.shape[0])

    def stretch(self) -> np.ndarray:
        """[T, 3, 3] symmetric stretch S (diag(scale) when there are no off-diagonal terms)."""
        return stretch_matrices(self.scale, self.stretch_offdiag)

    def matrices(self) -> np.ndarray:
        """[T, 4, 4] homogeneous matrices T * R * S."""
        if self.stretch_offdiag is None:
            rs = quat_to_matrix(self.rotation) * self.scale[:, None, :]
        else:
            rs = quat_to_matrix(self.rotation) @ self.stretch()
        out = np.zeros((self.count, 4, 4))
        out[:, :3, :3] = rs
        out[:, :3, 3] = self.translation
        out[:, 3, 3] = 1.0
        return out

    def take(self, index: np.ndarray | slice | int) -> "Pose":
        """The pose at a subset of the time samples (keeps the leading axis for ints); the
        off-diagonal terms are dropped where they are all zero at those samples."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1)
        off = None if self.stretch_offdiag is None else self.stretch_offdiag[index]
        return Pose(self.translation[index], self.rotation[index], self.scale[index], offdiag_or_none(off))

    def transform_points(self, points: np.ndarray) -> np.ndarray:
        """Map object-space points [V, 3] to world space at every time: [T, V, 3]."""
        if self.stretch_offdiag is None:
            stretched = points[None, :, :] * self.scale[:, None, :]
        else:
            stretched = np.einsum("tij,vj->tvi", self.stretch(), points)
        return quat_rotate(self.rotation[:, None, :], stretched) + self.translation[:, None, :]


def offdiag_or_none(off: np.ndarray | None) -> np.ndarray | None:
    """`off` as float64, or None when it is absent or exactly zero everywhere."""
    if off is None:
        return None
    off = np.asarray(off, dtype=np.float64)
    return off if off.any() else None


def stretch_matrices(scale: np.ndarray, offdiag: np.ndarray | None) -> np.ndarray:
    """[..., 3, 3] symmetric matrices from their diagonal [..., 3] and off-diagonal terms
    [..., 3] (S_xy, S_xz, S_yz; None: zero)."""
    scale = np.asarray(scale, dtype=np.float64)
    out = np.zeros(scale.shape[:-1] + (3, 3))
    out[..., [0, 1, 2], [0, 1, 2]] = scale
    if offdiag is not None:
        for k, (i, j) in enumerate(OFFDIAG):
            out[..., i, j] = out[..., j, i] = offdiag[..., k]
    return out


def stack_poses(poses: list[Pose]) -> Pose:
    """Poses [T] stacked along a new leading axis: [B, T, ...] (off-diagonal terms zero
    where a pose has none)."""
    offs = [q.stretch_offdiag for q in poses]
    off = None if all(o is None for o in offs) else np.stack([np.zeros_like(q.scale) if o is None else o for q, o in zip(poses, offs)])
    return Pose(np.stack([q.translation for q in poses]), np.stack([q.rotation for q in poses]), np.stack([q.scale for q in poses]), off)


def flatten_pose(pose: Pose) -> Pose:
    """A [B, T, ...] pose as [B * T, ...]."""
    return Pose(*(None if a is None else a.reshape(-1, a.shape[-1]) for a in pose))


def constant_pose(count: int, translation=(0.0, 0.0, 0.0), rotation=(1.0, 0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)) -> Pose:  # type: ignore[no-untyped-def]
    """A pose that does not change over `count` samples."""
    return Pose(
        np.broadcast_to(np.asarray(translation, dtype=np.float64), (count, 3)).copy(),
        np.broadcast_to(np.asarray(rotation, dtype=np.float64), (count, 4)).copy(),
        np.broadcast_to(np.asarray(scale, dtype=np.float64), (count, 3)).copy(),
    )


def compose(world_from_parent: Pose, parent_from_child: Pose) -> Pose:
    """world_from_child = world_from_parent * parent_from_child, exactly as 4x4 affine
    matrices (docs/motion.md, "Parent frames").

    T_p R_p S_p T_c R_c S_c = T(t_p + R_p S_p t_c) R_p R_c B with B = R_c^T S_p R_c S_c.
    Where the parent's stretch is uniform B = s_p S_c is the child's stretch (the old
    per-axis product, bit for bit). Otherwise B = U P (`polar_stretch`: U a rotation, P
    symmetric, positive definite unless B mirrors) gives rotation R_p R_c U and stretch P;
    a symmetric B (an unrotated child) is its own stretch. Every finite product is held
    exactly; a non-finite one raises UnrepresentablePoseError."""
    p, c = world_from_parent, parent_from_child
    if p.stretch_offdiag is None:
        stretched_t = p.scale * c.translation
    else:
        stretched_t = np.einsum("tij,tj->ti", p.stretch(), c.translation)
    # T_p R_p S_p (T_c x) = t_p + R_p (S_p t_c): the child's origin in world space.
    translation = p.translation + quat_rotate(p.rotation, stretched_t)
    rotation = quat_normalize(quat_mul(p.rotation, c.rotation))
    scale = p.scale * c.scale
    general = _needs_matrices(p, c)
    if not general.any():
        return Pose(translation, rotation, scale)
    k = np.nonzero(general)[0]
    r_c = quat_to_matrix(c.rotation[k])
    b = np.swapaxes(r_c, -1, -2) @ stretch_matrices(p.scale[k], _rows(p.stretch_offdiag, k)) @ r_c
    b = b @ stretch_matrices(c.scale[k], _rows(c.stretch_offdiag, k))
    u, stretch = polar_stretch(b)
    rotation[k] = quat_normalize(quat_mul(rotation[k], matrix_to_quat(u)))
    scale[k] = stretch[:, [0, 1, 2], [0, 1, 2]]
    off = np.zeros_like(scale)
    off[k] = np.stack([stretch[:, i, j] for i, j in OFFDIAG], axis=-1)
    return Pose(translation, rotation, scale, offdiag_or_none(off))


def _rows(off: np.ndarray | None, k: np.ndarray) -> np.ndarray | None:
    return None if off is None else off[k]


def _needs_matrices(p: Pose, c: Pose) -> np.ndarray:
    """[T] bool: the samples where the per-axis product is not the exact stretch: the
    parent's stretch is not uniform (or either has off-diagonal terms)."""
    s = p.scale
    general = (s[:, 0] != s[:, 1]) | (s[:, 0] != s[:, 2])
    for off in (p.stretch_offdiag, c.stretch_offdiag):
        if off is not None:
            general |= off.any(axis=-1)
    return general


def polar_stretch(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """b [K, 3, 3] = U S with U a rotation and S symmetric, exactly, for any finite b.

    The right polar decomposition (as scipy.linalg.polar), batched through numpy's SVD
    b = W diag(sigma) V^T: U = W V^T, S = V diag(sigma) V^T, S positive definite where
    det(b) > 0. Where det(b) < 0 (a mirror) W V^T would be a reflection: the last singular
    pair changes sign, b = (W D) (D diag(sigma)) V^T with D = diag(1, 1, -1), so U stays a
    rotation and S takes the mirror as one negative eigenvalue, as a negative `scale` does;
    a singular b gets a rotation too. A b that is already symmetric is its own S (U = I).
    Raises UnrepresentablePoseError (samples: rows of b) where b is not finite."""
    finite = np.isfinite(b).all(axis=(-2, -1))
    if not finite.all():
        raise UnrepresentablePoseError("the composed transform is not finite", np.nonzero(~finite)[0])
    size = np.abs(b).max(axis=(-2, -1))
    asym = np.abs(b - np.swapaxes(b, -1, -2)).max(axis=(-2, -1)) > SYMMETRY_TOLERANCE * size
    u = np.broadcast_to(np.eye(3), b.shape).copy()
    stretch = 0.5 * (b + np.swapaxes(b, -1, -2))
    if asym.any():
        w, sigma, vt = np.linalg.svd(b[asym])
        sign = np.where(np.linalg.det(w @ vt) < 0, -1.0, 1.0)
        w[:, :, 2] *= sign[:, None]
        sigma[:, 2] *= sign
        u[asym] = w @ vt
        p = np.swapaxes(vt, -1, -2) @ (sigma[:, :, None] * vt)
        stretch[asym] = 0.5 * (p + np.swapaxes(p, -1, -2))
    return u, stretch


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """[..., 3, 3] rotation matrices -> [..., 4] unit quaternions (w, x, y, z), each from
    the largest of 1 + trace and the diagonal terms (Shepperd's method), batched."""
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # 4 w^2 = 1 + tr, 4 x^2 = 1 + m00 - m11 - m22, ...; the largest gives a stable root
    cand = np.stack([
        np.stack([1 + m00 + m11 + m22, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        np.stack([m[..., 2, 1] - m[..., 1, 2], 1 + m00 - m11 - m22, m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        np.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 - m00 + m11 - m22, m[..., 1, 2] + m[..., 2, 1]], -1),
        np.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1], 1 - m00 - m11 + m22], -1),
    ], -2)
    pick = np.argmax(np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1), axis=-1)
    q = np.take_along_axis(cand, pick[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


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
# host's float64 resolves sin(theta) to 1e-6; the render kernel's float32 (render/poses/kernel.py
# `slerp`: this `slerp_with`, on drjit's operations) loses sin((1 - f) theta) / sin(theta) to
# rounding below about 1e-4.
SLERP_LINEAR_BELOW = {"float64": 1e-6, "float32": 1e-4}


class ArrayOps(NamedTuple):
    """The operations `slerp_with` needs from an array library (numpy here, drjit in the
    render kernel), and the precision's threshold of `SLERP_LINEAR_BELOW`."""

    dot: Callable[[Any, Any], Any]  # [..., 4] x [..., 4] -> [..., 1] (or a scalar per lane)
    where: Callable[[Any, Any, Any], Any]
    abs: Callable[[Any], Any]
    acos: Callable[[Any], Any]
    sin: Callable[[Any], Any]
    minimum: Callable[[Any, Any], Any]
    normalize: Callable[[Any], Any]
    linear_below: float


def slerp_with(ops: ArrayOps, q0: Any, q1: Any, s: Any) -> Any:
    """The one slerp: spherical linear interpolation of unit quaternions (w, x, y, z) with
    the shortest-path flip, s in [0, 1], on the operations of `ops`: (sin((1 - s) theta) q0
    + sin(s theta) q1) / sin(theta), a lerp where sin(theta) is below the precision's
    threshold, normalised."""
    dot = ops.dot(q0, q1)
    q1 = ops.where(dot < 0, -q1, q1)
    dot = ops.abs(dot)
    theta = ops.acos(ops.minimum(dot, 1.0))
    sin_theta = ops.sin(theta)
    small = sin_theta < ops.linear_below
    safe = ops.where(small, 1.0, sin_theta)
    a = ops.where(small, 1.0 - s, ops.sin((1.0 - s) * theta) / safe)
    b = ops.where(small, s, ops.sin(s * theta) / safe)
    return ops.normalize(a * q0 + b * q1)


NUMPY = ArrayOps(lambda a, b: np.sum(a * b, axis=-1, keepdims=True), np.where, np.abs, np.arccos, np.sin, np.minimum,
                 lambda q: quat_normalize(q), SLERP_LINEAR_BELOW["float64"])


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation [..., 4] with the shortest-path flip; s in [0, 1]
    (`slerp_with` on numpy, float64)."""
    return slerp_with(NUMPY, np.asarray(q0, dtype=float), np.asarray(q1, dtype=float), np.asarray(s, dtype=float)[..., None])


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
