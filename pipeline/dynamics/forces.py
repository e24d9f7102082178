"""Forces of D(t, X), each vectorised over bodies ([n, 3] arrays, SI units: N, m, s, kg).

Every function returns forces in newtons on each body (or, for friction, an impulse in
N s); the state derivative divides by mass. Energies are the matching potentials (J), used
by the stability guard and `motion plot --what energy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# O(n^2) memory and time: 3 * n^2 float64 temporaries, 96 MB at n = 2048.
NBODY_LIMIT = 2048


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (length 3), broadcasting: the arithmetic of np.cross
    (a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0) without its axis handling, which costs
    more than the products for the few bodies of a small system."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def gravity(mass: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Uniform gravity F = m g (N); g in m/s^2, default (0, -9.81, 0)."""
    return mass[:, None] * g[None, :]


def gravity_energy(mass: np.ndarray, g: np.ndarray, x: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
    """Potential of uniform gravity, per body: U = -m g . (x - x_ref) (J)."""
    return -mass * ((x - x_ref) @ g)


def newtonian_gravity(x: np.ndarray, mass: np.ndarray, G: float, softening: float) -> np.ndarray:
    """n-body attraction F_i = sum_j G m_i m_j (x_j - x_i) / (|x_j - x_i|^2 + s^2)^(3/2) (N).

    O(n^2) in time and memory; limited to NBODY_LIMIT bodies. s (m) is the softening length."""
    d = x[None, :, :] - x[:, None, :]  # d[i, j] = x_j - x_i
    r2 = np.einsum("ijk,ijk->ij", d, d) + softening * softening
    inv_r3 = np.zeros_like(r2)
    np.power(r2, -1.5, out=inv_r3, where=r2 > 0)
    np.fill_diagonal(inv_r3, 0.0)
    return G * mass[:, None] * np.einsum("ij,ijk->ik", mass[None, :] * inv_r3, d)


def newtonian_energy(x: np.ndarray, mass: np.ndarray, G: float, softening: float) -> float:
    """U = -sum_{i<j} G m_i m_j / sqrt(r^2 + s^2) (J), the potential of the softened force."""
    d = x[None, :, :] - x[:, None, :]
    r = np.sqrt(np.einsum("ijk,ijk->ij", d, d) + softening * softening)
    pair = G * np.outer(mass, mass) / np.where(r > 0, r, np.inf)
    return float(-0.5 * (pair.sum() - np.trace(pair)))


@dataclass(frozen=True)
class SpringSet:
    """Hooke springs between bodies a[k] and b[k] (indices), stiffness k (N/m), damping c
    (N s/m), rest length (m)."""

    a: np.ndarray
    b: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest: np.ndarray

    @property
    def count(self) -> int:
        """Number of springs."""
        return int(self.a.size)


def springs(x: np.ndarray, v: np.ndarray, s: SpringSet) -> np.ndarray:
    """F_a = (k (|d| - L) + c (v_b - v_a) . u) u, F_b = -F_a, with d = x_b - x_a, u = d/|d| (N).

    The damping acts along the spring only (it resists stretching rate, not swinging)."""
    out = np.zeros_like(x)
    if s.count == 0:
        return out
    d = x[s.b] - x[s.a]
    length = np.linalg.norm(d, axis=1)
    u = d / np.where(length > 0, length, 1.0)[:, None]
    rate = np.einsum("ij,ij->i", v[s.b] - v[s.a], u)
    f = (s.stiffness * (length - s.rest) + s.damping * rate)[:, None] * u
    np.add.at(out, s.a, f)
    np.add.at(out, s.b, -f)
    return out


def spring_energy(x: np.ndarray, s: SpringSet) -> np.ndarray:
    """U = 1/2 k (|d| - L)^2 per spring (J)."""
    if s.count == 0:
        return np.zeros(0)
    length = np.linalg.norm(x[s.b] - x[s.a], axis=1)
    return 0.5 * s.stiffness * (length - s.rest) ** 2


def drag(v_rel: np.ndarray, mass: np.ndarray, rho: float | np.ndarray, cd: np.ndarray, area: np.ndarray, linear: np.ndarray, h: float) -> np.ndarray:
    """Rayleigh drag -1/2 rho Cd A |v| v plus linear drag -k v, with v the velocity relative
    to the air or water (N).

    Never reverses v within a step: the deceleration is capped at |v| / h, so one step of
    any explicit integrator at most brings the relative velocity to zero."""
    # N s/m: F = -coeff v; coeff / m <= 1 / h  <=>  |a| = coeff |v| / m <= |v| / h
    coeff = drag_coefficient(v_rel, 0.5 * rho * cd * area, linear, mass / h if h > 0 else None)
    return -coeff[:, None] * v_rel


def drag_coefficient(v_rel: np.ndarray, quadratic: np.ndarray, linear: np.ndarray | None, cap: np.ndarray | float | None) -> np.ndarray:
    """Per body, quadratic |v_rel| + linear, at most `cap` (None: no cap; linear None: 0):
    drag's F = -coeff v with quadratic = 1/2 rho Cd A, or its deceleration a = -coeff v
    with every term divided by the mass. In place on one new array: a system of 100k
    particles pays for each pass over memory, not for the arithmetic."""
    coeff = np.sqrt(np.einsum("ij,ij->i", v_rel, v_rel))
    coeff *= quadratic
    if linear is not None:
        coeff += linear
    if cap is not None:
        np.minimum(coeff, cap, out=coeff)
    return coeff


@dataclass(frozen=True)
class HalfSpaceFluid:
    """Fluid below `level` along `up` (unit vector against gravity): density (kg/m^3), Cd."""

    level: float
    density: float
    cd: float


def sphere_cap_volume(depth: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Volume of a sphere of `radius` below a plane `depth` above its lowest point:
    V = pi h^2 (3 r - h) / 3 with h clamped to [0, 2 r] (m^3)."""
    h = np.clip(depth, 0.0, 2.0 * radius)
    return math.pi * h * h * (3.0 * radius - h) / 3.0


def _cap_volume_integral(depth: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """W(h) = integral_0^h V(h') dh' = pi (r h^3 - h^4 / 4) / 3 for h <= 2r, then linear."""
    h = np.clip(depth, 0.0, 2.0 * radius)
    inside = math.pi * (radius * h**3 - h**4 / 4.0) / 3.0
    full = 4.0 / 3.0 * math.pi * radius**3
    return inside + full * np.maximum(depth - 2.0 * radius, 0.0)


def buoyancy(x: np.ndarray, radius_eq: np.ndarray, fluid: HalfSpaceFluid, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Archimedes: F = rho_fluid V_sub |g| up (N), the body as a sphere of its own volume
    (radius_eq). Returns (force, submerged fraction V_sub / V)."""
    g_mag = float(np.linalg.norm(g))
    if g_mag == 0:
        return np.zeros_like(x), np.zeros(len(x))
    up = -g / g_mag
    depth = fluid.level - (x @ up - radius_eq)  # how far the lowest point is under the surface
    v_sub = sphere_cap_volume(depth, radius_eq)
    fraction = v_sub / (4.0 / 3.0 * math.pi * radius_eq**3)
    return (fluid.density * g_mag * v_sub)[:, None] * up[None, :], fraction


def buoyancy_energy(x: np.ndarray, radius_eq: np.ndarray, fluid: HalfSpaceFluid, g: np.ndarray) -> np.ndarray:
    """Potential of buoyancy: U = -rho |g| W(depth), since dU/d(depth) = -rho |g| V_sub (J)."""
    g_mag = float(np.linalg.norm(g))
    if g_mag == 0:
        return np.zeros(len(x))
    up = -g / g_mag
    depth = fluid.level - (x @ up - radius_eq)
    return -fluid.density * g_mag * _cap_volume_integral(depth, radius_eq)


def field_force(mass: np.ndarray, field: tuple[object, object, object] | None, t: float, x: np.ndarray) -> np.ndarray:
    """A user force field f(t, x, y, z) in N/kg (three expressions): F = m f (N)."""
    if field is None:
        return np.zeros_like(x)
    values = {"t": t, "x": x[:, 0], "y": x[:, 1], "z": x[:, 2]}
    f = np.stack([expr.evaluate(values, shape=(len(x),)) for expr in field], axis=1)  # type: ignore[attr-defined]
    return mass[:, None] * f


def wind_velocity(wind: tuple[object, object, object] | None, t: float, x: np.ndarray) -> np.ndarray:
    """Air velocity u(t, x, y, z) in m/s (three expressions); drag acts on v - u."""
    if wind is None:
        return np.zeros_like(x)
    values = {"t": t, "x": x[:, 0], "y": x[:, 1], "z": x[:, 2]}
    return np.stack([expr.evaluate(values, shape=(len(x),)) for expr in wind], axis=1)  # type: ignore[attr-defined]


def coulomb_friction(slip: np.ndarray, normal_impulse: np.ndarray, k_t: np.ndarray, mu_k: np.ndarray, mu_s: np.ndarray) -> np.ndarray:
    """Friction impulse magnitude (N s) against a tangential slip speed (m/s) at a contact.

    Stopping the slip needs j_stop = |u_t| / k_t (k_t: inverse effective mass along the
    slip, 1/kg). Static: if j_stop <= mu_s j_n, the contact sticks (j = j_stop). Kinetic:
    j = mu_k j_n, capped at j_stop so friction never reverses the slip within a step."""
    j_stop = np.where(k_t > 0, slip / np.where(k_t > 0, k_t, 1.0), 0.0)
    sticks = j_stop <= mu_s * normal_impulse
    return np.where(sticks, j_stop, np.minimum(mu_k * normal_impulse, j_stop))
