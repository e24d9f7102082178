"""Rigid-body kinematics: quaternions (w, x, y, z), inertia tensors from shape and mass,
the orientation rate and gyroscopic term of D(t, X), and slerp for sampling.

All functions are vectorised over a leading body axis; nothing loops over bodies."""

from __future__ import annotations

import math

import numpy as np

# --- quaternions (w, x, y, z) -------------------------------------------------------------


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b over the last axis ([..., 4])."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        axis=-1,
    )


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions; a zero quaternion becomes the identity."""
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), 0.0)
    out[..., 0] = np.where(norm[..., 0] > 0, out[..., 0], 1.0)
    return out


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices [..., 3, 3] of unit quaternions [..., 4] (world_from_body)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), axis=-1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), axis=-1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )


def quat_rate(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """dq/dt for a world-frame angular velocity omega (rad/s).

    Derivation: q(t + dt) = [cos(|w|dt/2), sin(|w|dt/2) w/|w|] * q(t) -> dq/dt = 0.5 (0, w) * q."""
    pure = np.concatenate((np.zeros(omega.shape[:-1] + (1,)), omega), axis=-1)
    return 0.5 * quat_mul(pure, q)


def quat_from_rotation(rotate: object) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a scene `rotate:` value (None is the identity)."""
    from scipy.spatial.transform import Rotation

    if rotate is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    if hasattr(rotate, "quaternion"):
        q = np.asarray(rotate.quaternion, dtype=np.float64)
        return q / np.linalg.norm(q)
    if hasattr(rotate, "euler"):
        r = Rotation.from_euler(rotate.order, rotate.euler, degrees=True)
    else:
        axis = np.asarray(rotate.axis, dtype=np.float64)
        r = Rotation.from_rotvec(axis / np.linalg.norm(axis) * math.radians(rotate.angle))
    x, y, z, w = r.as_quat()  # scipy is scalar-last
    return np.array([w, x, y, z])


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation [..., 4] with the shortest-path flip; s in [0, 1]."""
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    s = np.asarray(s)[..., None]
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    safe = np.where(small, 1.0, sin_theta)
    a = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    b = np.where(small, s, np.sin(s * theta) / safe)
    return quat_normalize(a * q0 + b * q1)


# --- inertia ------------------------------------------------------------------------------


def principal_inertia(shape: str, mass: float, dims: dict[str, float]) -> np.ndarray:
    """Principal moments (Ixx, Iyy, Izz) in kg m^2 about the object's own axes.

    sphere 2/5 m r^2; box m/12 (b^2 + c^2) ...; cylinder along +Y: Iyy = m r^2 / 2,
    Ixx = Izz = m (3 r^2 + h^2) / 12; thin rectangle in XY: m/12 (h^2, w^2, w^2 + h^2);
    disk in XY: m r^2 (1/4, 1/4, 1/2); a mesh uses the solid box of its bounds."""
    m = mass
    if shape == "sphere":
        i = 0.4 * m * dims["radius"] ** 2
        return np.array([i, i, i])
    if shape in ("cube", "mesh"):
        a, b, c = dims["sx"], dims["sy"], dims["sz"]
        return m / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    if shape == "cylinder":
        r, h = dims["radius"], dims["height"]
        side = m * (3 * r * r + h * h) / 12.0
        return np.array([side, 0.5 * m * r * r, side])
    if shape == "rectangle":
        w, h = dims["width"], dims["height"]
        return m / 12.0 * np.array([h * h, w * w, w * w + h * h])
    if shape == "disk":
        r = dims["radius"]
        return m * r * r * np.array([0.25, 0.25, 0.5])
    # a point-like thing (empty): a small solid sphere of 5 cm keeps I invertible
    i = 0.4 * m * 0.05**2
    return np.array([i, i, i])


def inverse_inertia_world(q: np.ndarray, inv_inertia_body: np.ndarray) -> np.ndarray:
    """I_world^-1 = R diag(I_body^-1) R^T, [n, 3, 3]."""
    rot = quat_to_matrix(quat_normalize(q))
    return np.einsum("nij,nj,nkj->nik", rot, inv_inertia_body, rot)


def angular_acceleration(q: np.ndarray, omega: np.ndarray, inertia_body: np.ndarray, inv_inertia_body: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """Euler's equations in world frame: dw/dt = I^-1 (tau - w x (I w)), I = R diag(I_b) R^T.

    q is normalised first: Runge-Kutta stages see unnormalised quaternions, whose matrix
    would not be a rotation (and would make an isotropic body look anisotropic)."""
    rot = quat_to_matrix(quat_normalize(q))
    w_body = np.einsum("nji,nj->ni", rot, omega)  # R^T w
    tau_body = np.einsum("nji,nj->ni", rot, torque)
    alpha_body = inv_inertia_body * (tau_body - np.cross(w_body, inertia_body * w_body))
    return np.einsum("nij,nj->ni", rot, alpha_body)
