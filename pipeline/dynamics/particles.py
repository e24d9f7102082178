"""Particle systems: seeded emitters, spawned and simulated as one vectorised group.

Particle i of an emitter is born at start + i / rate (while before `stop`, up to
`max_count`) and lives `lifetime` seconds; its spawn position (a point or uniform in a box
of `size`), speed (speed +- speed_spread, uniform) and direction (uniform over the
spherical cap of half-angle `spread` about `direction`) are drawn up front from
numpy's PCG64 seeded with `seed`, in the emitter object's frame: the same seed gives
the same particles, whatever the step. A particle born inside a step joins at the next
step boundary on its exact ballistic path (x0 + v0 tau + g tau^2 / 2), so spawns do not
band at the step rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class ParticleSamples(NamedTuple):
    """Particles of one system at sample times: ids [n] (spawn order), positions [T, n, 3]
    (world space; before birth the spawn point, after death where it died), alive [T, n]."""

    ids: np.ndarray
    positions: np.ndarray
    alive: np.ndarray


@dataclass(frozen=True)
class Spawns:
    """Everything about each particle fixed at emission: birth time (s), death time (s),
    position (m) and velocity (m/s) at birth, world space."""

    birth: np.ndarray
    death: np.ndarray
    position: np.ndarray
    velocity: np.ndarray

    @property
    def count(self) -> int:
        """Number of particles."""
        return int(self.birth.size)


def _orthonormal(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(d, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(d, a)


def emit(emitter: object, world_from_object: np.ndarray, t_end: float, epoch: float = 0.0) -> Spawns:
    """Draw every particle the emitter spawns before min(stop, t_end). `emitter` is a scene
    ParticleEmitter; world_from_object a 4x4 matrix (the particle object's transform);
    the emitter's `start`/`stop` count from `epoch`, the scene time of the shot's first
    frame (world.shot_start)."""
    e = emitter
    start = epoch + e.start  # type: ignore[attr-defined]
    stop = t_end if e.stop is None else min(epoch + e.stop, t_end)  # type: ignore[attr-defined]
    count = 0 if stop < start else min(e.max_count, int(math.floor((stop - start) * e.rate)) + 1)  # type: ignore[attr-defined]
    rng = np.random.Generator(np.random.PCG64(e.seed))  # type: ignore[attr-defined]
    i = np.arange(count)
    birth = start + i / e.rate  # type: ignore[attr-defined]
    birth = birth[birth <= stop] if count else birth
    count = birth.size
    u = rng.random((count, 3))
    local_pos = np.asarray(e.position) + (u - 0.5) * np.asarray(e.size)  # type: ignore[attr-defined]
    d = np.asarray(e.direction, dtype=np.float64)  # type: ignore[attr-defined]
    norm = np.linalg.norm(d)
    d = d / norm if norm > 0 else np.array([0.0, 1.0, 0.0])
    a, b = _orthonormal(d)
    # uniform on the cap: cos(theta) uniform in [cos(spread), 1]
    cos_max = math.cos(math.radians(e.spread))  # type: ignore[attr-defined]
    cos_t = 1.0 - rng.random(count) * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = rng.random(count) * 2.0 * math.pi
    direction = cos_t[:, None] * d + (sin_t * np.cos(phi))[:, None] * a + (sin_t * np.sin(phi))[:, None] * b
    speed = e.speed + e.speed_spread * (2.0 * rng.random(count) - 1.0)  # type: ignore[attr-defined]
    local_vel = direction * np.maximum(speed, 0.0)[:, None]
    linear = world_from_object[:3, :3]
    position = local_pos @ linear.T + world_from_object[:3, 3]
    velocity = local_vel @ linear.T
    return Spawns(birth, birth + e.lifetime, position, velocity)  # type: ignore[attr-defined]


def ballistic(spawns: Spawns, index: np.ndarray, t: float, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of particles `index` at time t on their free-flight path from
    birth: x0 + v0 tau + g tau^2 / 2, v0 + g tau (tau = t - birth, may be negative)."""
    tau = (t - spawns.birth[index])[:, None]
    return spawns.position[index] + spawns.velocity[index] * tau + 0.5 * g * tau * tau, spawns.velocity[index] + g * tau
