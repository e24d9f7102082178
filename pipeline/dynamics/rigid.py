"""Rigid-body kinematics: quaternions (w, x, y, z), world inertia tensors from the
principal moments (which pipeline/geometry.py gives per shape), the orientation rate and
the gyroscopic term of D(t, X).

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






# --- inertia (principal moments per shape: pipeline/geometry.py) ------------------------


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
