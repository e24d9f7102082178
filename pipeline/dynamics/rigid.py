"""Rigid-body kinematics: quaternions (w, x, y, z), inertia tensors from shape and mass,
the orientation rate and gyroscopic term of D(t, X), and slerp for sampling.

All functions are vectorised over a leading body axis; nothing loops over bodies."""

from __future__ import annotations

import numpy as np

from ..motion.pose import quat_mul, quat_normalize, quat_to_matrix
from .forces import cross

# --- quaternions (w, x, y, z) -------------------------------------------------------------








def quat_rate(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """dq/dt for a world-frame angular velocity omega (rad/s).

    Derivation: q(t + dt) = [cos(|w|dt/2), sin(|w|dt/2) w/|w|] * q(t) -> dq/dt = 0.5 (0, w) * q."""
    pure = np.concatenate((np.zeros(omega.shape[:-1] + (1,)), omega), axis=-1)
    return 0.5 * quat_mul(pure, q)






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


def isotropic(moments: np.ndarray) -> bool:
    """True when every body's three principal moments are equal (spheres, [n, 3])."""
    return bool((moments == moments[:, :1]).all())


def inverse_inertia_world(q: np.ndarray, inv_inertia_body: np.ndarray) -> np.ndarray:
    """I_world^-1 = R diag(I_body^-1) R^T, [n, 3, 3]. Isotropic bodies (spheres):
    R (c 1) R^T = c 1 whatever R, so no rotation is computed when every body is one."""
    if isotropic(inv_inertia_body):
        return inv_inertia_body[:, 0, None, None] * np.eye(3)
    rot = quat_to_matrix(quat_normalize(q))
    return np.einsum("nij,nj,nkj->nik", rot, inv_inertia_body, rot)


def angular_acceleration(q: np.ndarray, omega: np.ndarray, inertia_body: np.ndarray, inv_inertia_body: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """Euler's equations in world frame: dw/dt = I^-1 (tau - w x (I w)), I = R diag(I_b) R^T.

    q is normalised first: Runge-Kutta stages see unnormalised quaternions, whose matrix
    would not be a rotation (and would make an isotropic body look anisotropic).
    Isotropic bodies: w x (i w) = 0 and I^-1 = 1/i in any frame, so dw/dt = tau / i."""
    if isotropic(inertia_body):
        return inv_inertia_body * torque
    rot = quat_to_matrix(quat_normalize(q))
    w_body = np.einsum("nji,nj->ni", rot, omega)  # R^T w
    tau_body = np.einsum("nji,nj->ni", rot, torque)
    alpha_body = inv_inertia_body * (tau_body - cross(w_body, inertia_body * w_body))
    return np.einsum("nij,nj->ni", rot, alpha_body)
