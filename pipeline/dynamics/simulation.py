"""`simulate(loaded, t_end)` -> `Simulation`: build the world from the scene (world.py), run
each group through the step stages (step.py), and keep the recorded tracks (track.py),
sampled at any times.

Bodies and each particle system are separate groups: particles collide with the colliders
and with the bodies at their recorded poses (one way: they do not act on bodies), so the
bodies run first and each particle system after them. Flocks
(flock.py) and planned-path followers (follower.py) are simulated here too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import NoSuchTrackError, SimulationError
from ..motion.pose import Pose
from .follower import FollowerTrack, simulate_follower
from .guard import Guard
from .integrators import make_integrator
from .particles import ParticleSamples, Spawns, emit
from .step import run_group
from .track import Track
from .world import body_colliders, build_bodies, build_colliders, emitter_group, shot_start, static_matrix

if TYPE_CHECKING:
    from ..scene import LoadedScene


@dataclass
class ParticleSystem:
    """One particle object's simulation: its spawns and its recorded track."""

    name: str
    spawns: Spawns
    track: Track


@dataclass
class Simulation:
    """Recorded dynamics of a scene between t_start and t_end, sampled at any times.

    Times outside [t_start, t_end] are clamped (bodies hold their first / last state)."""

    t_start: float
    t_end: float
    integrator: str
    step: float
    body_names: list[str]
    body_scales: list[np.ndarray]
    bodies: Track | None
    systems: dict[str, ParticleSystem]
    collider_names: list[str]
    gravity: np.ndarray | None = None  # m/s^2
    body_mass: np.ndarray | None = None  # kg, per body
    body_start: np.ndarray | None = None  # [n, 3] m, where each body's gravity potential was zero in the track
    flocks: dict[str, "object"] = field(default_factory=dict)  # FlockTrack by object name (flock.py)
    followers: dict[str, FollowerTrack] = field(default_factory=dict)  # by planned object name

    def follower(self, name: str) -> FollowerTrack:
        """The simulated follower (follower.py FollowerTrack) of the planned object `name`."""
        if name not in self.followers:
            raise NoSuchTrackError(f"no planned-path follower named '{name}' (have: {', '.join(self.followers) or 'none'})")
        return self.followers[name]

    def flock(self, name: str) -> "object":
        """The recorded agents (flock.FlockTrack) of the flock object `name`."""
        if name not in self.flocks:
            raise NoSuchTrackError(f"no flock named '{name}' (have: {', '.join(self.flocks) or 'none'})")
        return self.flocks[name]

    def sample(self, times: np.ndarray) -> dict[str, Pose]:
        """World-space Pose of every dynamics body at `times` (seconds, any order)."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        if self.bodies is None:
            return {}
        x, q = self.bodies.interpolate(times)
        if q is None:
            raise RuntimeError("rigid-body track without orientations (dynamics/track.py)")
        return {
            name: Pose(np.ascontiguousarray(x[:, i]), np.ascontiguousarray(q[:, i]), np.broadcast_to(self.body_scales[i], (times.size, 3)).copy())
            for i, name in enumerate(self.body_names)
        }

    def particles(self, name: str, times: np.ndarray) -> ParticleSamples:
        """Particles of the system `name` at `times`: ids, positions [T, n, 3], alive [T, n]."""
        if name not in self.systems:
            raise NoSuchTrackError(f"no particle system named '{name}' (have: {', '.join(self.systems) or 'none'})")
        ps = self.systems[name]
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        n = ps.spawns.count
        if n == 0:
            return ParticleSamples(np.zeros(0, dtype=np.int64), np.zeros((times.size, 0, 3)), np.zeros((times.size, 0), dtype=bool))
        alive = (times[:, None] >= ps.spawns.birth[None, :] - 1e-12) & (times[:, None] < ps.spawns.death[None, :])
        # before birth: at the spawn point; after death: where it died
        clamped = np.clip(times[:, None], ps.spawns.birth[None, :], ps.spawns.death[None, :])
        x, _ = ps.track.interpolate(clamped)
        return ParticleSamples(np.arange(n, dtype=np.int64), x, alive)

    @property
    def particle_systems(self) -> list[str]:
        """Names of the particle objects simulated."""
        return list(self.systems)

    def body_energy(self) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """(body, times, kinetic, potential) per dynamics body, in J. The potential's zero
        is the plane through the world origin perpendicular to gravity (height 0 for
        g along -Y): U = -m g . x, plus buoyancy. Shared terms (springs, gravity between
        bodies) are not in any one body's energy: `energy()` has the group's total."""
        b = self.bodies
        if b is None or b.kinetic_each is None or self.gravity is None:
            return []
        # the track's potential is zero at each body's start: shift by -m g . x_start
        shift = -self.body_mass * (self.body_start @ self.gravity)
        return [(name, b.times, b.kinetic_each[:, i], b.potential_each[:, i] + shift[i]) for i, name in enumerate(self.body_names)]

    def energy(self) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """(label, times, kinetic, potential) per group, in J, for plots."""
        out = []
        if self.bodies is not None:
            out.append(("bodies", self.bodies.times, self.bodies.kinetic, self.bodies.potential))
        for name, ps in self.systems.items():
            out.append((name, ps.track.times, ps.track.kinetic, ps.track.potential))
        return out


def simulate(loaded: "LoadedScene", t_end: float, t_start: float = 0.0, on_progress: Callable[[float, float, float], None] | None = None) -> Simulation:
    """Simulate every dynamics body and particle system of the scene from t_start to t_end.

    `on_progress(t, t_start, t_end)` is called every few steps of each group (bodies first,
    then each particle system) with the time simulated so far."""
    if not (math.isfinite(t_start) and math.isfinite(t_end)) or t_end < t_start:
        raise SimulationError(f"cannot simulate from t = {t_start} s to t = {t_end} s")
    d = loaded.scene.dynamics
    integrator = make_integrator(d.integrator, d.rtol, d.atol)
    g_mag = float(np.linalg.norm(d.gravity))
    colliders = build_colliders(loaded, t_start)
    built = build_bodies(loaded, t_start, colliders)
    track, names, scales = None, [], []
    mass = start = None
    if built is not None:
        group, scales = built
        names = group.system.props.names
        p = group.system.props
        mass, start = p.mass.copy(), group.system.x_ref.copy()
        guard = Guard(names, d.integrator, d.energy_growth_limit, 0.0, float((p.mass * g_mag * p.radius).sum()) + 1e-9)
        track = run_group(group, integrator, t_start, t_end, d.step, d.contact_iterations, guard, on_progress, d.rk45_max_steps)
    systems: dict[str, ParticleSystem] = {}
    # particles also bounce off the bodies, at the bodies' recorded poses (one way)
    seen_by_particles = colliders + (body_colliders(group, track, d.step) if track is not None else [])
    for i, obj in enumerate(loaded.scene.objects):
        if obj.shape != "particles":
            continue
        m = static_matrix(loaded, i, "a particle emitter")
        spawns = emit(obj.emitter, m, t_end, shot_start(loaded))
        group = emitter_group(loaded, i, spawns, seen_by_particles, t_start, t_end, d.step)
        p = group.system.props
        guard = Guard([f"{obj.name}[{k}]" for k in range(spawns.count)] if spawns.count <= 100_000 else [obj.name], d.integrator, d.energy_growth_limit, 0.0,
                      float((p.mass * g_mag * np.maximum(p.radius, 1e-3)).sum()) + 1e-9)
        systems[obj.name] = ParticleSystem(obj.name, spawns, run_group(group, integrator, t_start, t_end, d.step, d.contact_iterations, guard, on_progress))
    flocks: dict[str, object] = {}
    for i, obj in enumerate(loaded.scene.objects):
        if obj.is_flock:
            from ..motion.instances import check_instance_budget
            from .flock import FlockParams, simulate_flock

            check_instance_budget(loaded, i)
            flocks[obj.name] = simulate_flock(FlockParams.from_spec(obj.deform, shot_start(loaded)), [c for c in colliders if c.motion is None], t_start, t_end, obj.name)
    followers: dict[str, FollowerTrack] = {}
    for i, obj in enumerate(loaded.scene.objects):
        if obj.motion.type == "plan" and obj.motion.follower is not None:
            followers[obj.name] = simulate_follower(loaded, i, t_start, t_end)
    return Simulation(t_start, t_end, d.integrator, d.step, names, scales, track, systems, [c.name for c in colliders],
                      np.asarray(d.gravity, dtype=np.float64), mass, start, flocks, followers)
