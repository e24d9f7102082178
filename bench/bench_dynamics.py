"""Dynamics benchmark: particle-steps per second for 100,000 particles under gravity +
Rayleigh drag + a ground plane (RK4 and semi-implicit Euler), against
scipy.integrate.solve_ivp on the same gravity + drag system; the n-body force cost vs n;
peak memory of the 100k run; with --stack, the "ten books" stack instead: CPU seconds per
simulated second and the largest displacement of a box, impulses and penalty contacts.
Run: python bench/bench_dynamics.py [--particles N] [--stack SECONDS]"""

from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import cpu_model  # noqa: E402
from motion.pipeline.dynamics import forces  # noqa: E402
from motion.pipeline.dynamics.collisions import PlaneCollider  # noqa: E402
from motion.pipeline.dynamics.guard import Guard  # noqa: E402
from motion.pipeline.dynamics.integrators import make_integrator  # noqa: E402
from motion.pipeline.dynamics.particles import Spawns  # noqa: E402
from motion.pipeline.dynamics.step import StepDynamics, run_group  # noqa: E402
from motion.pipeline.dynamics.world import particle_group  # noqa: E402
from motion.pipeline.dynamics.state import BodyProps, Environment, System  # noqa: E402

G = np.array([0.0, -9.81, 0.0])
RADIUS, MASS, CD = 0.01, 0.001, 0.47


def particle_system(n: int) -> tuple[System, Spawns]:
    rng = np.random.default_rng(0)
    area = math.pi * RADIUS**2
    props = BodyProps(
        names=[], mass=np.full(n, MASS), inv_mass=np.full(n, 1 / MASS), radius=np.full(n, RADIUS), radius_eq=np.full(n, RADIUS),
        area=np.full(n, area), cd=np.full(n, CD), linear=np.zeros(n), restitution=np.full(n, 0.5), friction=np.full(n, 0.3),
        static_friction=np.full(n, 0.3), start=np.zeros(n), inertia=np.zeros((n, 3)), inv_inertia=np.zeros((n, 3)),
    )
    system = System(props, Environment(gravity=G), rotating=False)
    pos = rng.uniform([-5, 1, -5], [5, 5, 5], (n, 3))
    vel = rng.normal(0, 3, (n, 3))
    return system, Spawns(np.zeros(n), np.full(n, 1e9), pos, vel)


def run_ours(n: int, integrator: str, steps: int, h: float, plane: bool) -> tuple[float, float]:
    system, spawns = particle_system(n)
    colliders = [PlaneCollider(name="ground", restitution=0.5, friction=0.3, static_friction=0.3)] if plane else []
    group = particle_group(system, spawns, colliders, 0.0, steps * h, h)
    guard = Guard(["p"], integrator, 10.0, 0.0, 1.0)
    start = time.perf_counter()
    track = run_group(group, make_integrator(integrator), 0.0, steps * h, h, 4, guard)
    elapsed = time.perf_counter() - start
    assert np.isfinite(track.x).all()
    return n * steps / elapsed, elapsed


def run_scipy(n: int, steps: int, h: float, method: str) -> tuple[float, float, int]:
    system, spawns = particle_system(n)
    system.active = np.ones(n, dtype=bool)
    dynamics = StepDynamics(system, h)
    X0 = system.pack(spawns.position, spawns.velocity)
    start = time.perf_counter()
    sol = solve_ivp(dynamics.derivative, (0.0, steps * h), X0, method=method, t_eval=np.arange(1, steps + 1) * h, rtol=1e-6, atol=1e-9)
    elapsed = time.perf_counter() - start
    return n * steps / elapsed, elapsed, int(sol.nfev)


def run_stack(contact: str, integrator: str, step: float, seconds: float) -> tuple[float, float]:
    """Ten 0.2 m, 1 kg boxes stacked on a floor (exactly touching; penalty: the default 10 ms
    contact, placed at its resting compression): CPU seconds per simulated second and the
    largest displacement of any box (m)."""
    import yaml

    from motion.pipeline.dynamics import simulate
    from motion.pipeline.scene import load_scene

    k = (math.pi / 0.01) ** 2
    sink = np.cumsum((10 - np.arange(10)) * 9.81 / (4 * k)) if contact == "penalty" else np.zeros(10)
    objects = [{"name": f"b{i}", "shape": "cube", "size": 0.2, "transform": {"translate": [0, 0.1 + 0.2 * i - float(sink[i]), 0]},
                "motion": {"type": "dynamics", "body": "rigid", "mass": 1.0, "restitution": 0.0, "friction": 0.5, "contact": contact}}
               for i in range(10)]
    objects.append({"name": "floor", "shape": "rectangle", "width": 100, "height": 100, "collider": {"restitution": 0.0, "friction": 0.5},
                    "transform": {"rotate": {"euler": [-90, 0, 0]}}})
    doc = {"name": "stack", "timeline": {"fps": 24, "first": 0, "last": 24}, "camera": {"position": [0, 1, 10], "look_at": [0, 0, 0]},
           "objects": objects, "dynamics": {"integrator": integrator, "step": step}}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "stack.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        loaded = load_scene(path)
        start = time.process_time()
        tr = simulate(loaded, seconds).bodies
        cpu = time.process_time() - start
    return cpu / seconds, float(np.linalg.norm(tr.x - tr.x[0], axis=2).max())


def stack_main(seconds: float) -> None:
    """The --stack report."""
    print(f"# {cpu_model()}, {os.cpu_count()} cores")
    print(f"# ten 0.2 m boxes stacked on a floor, {seconds:g} s simulated")
    for contact, integrator, step in (("impulse", "rk4", 0.002), ("impulse", "semi-implicit-euler", 0.002),
                                      ("penalty", "semi-implicit-euler", 0.0005), ("penalty", "rk4", 0.0005)):
        try:
            rate, drift = run_stack(contact, integrator, step, seconds)
            print(f"{contact:8s} {integrator:20s} h = {step:g} s: {rate:7.2f} CPU s per simulated s, largest displacement {drift:.3g} m")
        except Exception as exc:  # the stack before this change could blow up: say so, go on
            print(f"{contact:8s} {integrator:20s} h = {step:g} s: {type(exc).__name__}: {str(exc)[:120]}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--particles", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--stack", type=float, default=None, help="simulate the ten-box stack for this many seconds instead")
    args = ap.parse_args()
    if args.stack is not None:
        stack_main(args.stack)
        return
    n, steps, h = args.particles, args.steps, 1 / 480
    print(f"# {cpu_model()}, {os.cpu_count()} cores")
    print(f"# {n} particles, {steps} steps of {h:.5f} s, gravity + drag (+ ground plane); median of {args.repeat} runs after a warm-up")
    run_ours(n, "semi-implicit-euler", 5, h, True)  # the process's first big allocations: not the simulation's cost
    results = {}
    for integ in ("semi-implicit-euler", "rk4"):
        for plane in (True, False):
            runs = sorted(run_ours(n, integ, steps, h, plane) for _ in range(args.repeat))
            rate, el = runs[len(runs) // 2]
            results[(integ, plane)] = rate
            print(f"ours {integ:20s} plane={plane!s:5s}: {rate / 1e6:7.2f} M particle-steps/s ({el:.2f} s)")
    for method in ("RK45", "RK23"):
        rate, el, nfev = run_scipy(n, steps, h, method)
        results[("scipy", method)] = rate
        print(f"scipy solve_ivp {method} (no plane): {rate / 1e6:7.2f} M particle-steps/s ({el:.2f} s, {nfev} D evaluations)")
    print(f"ratio ours rk4 (no plane) / scipy RK45: {results[('rk4', False)] / results[('scipy', 'RK45')]:.2f}")
    print(f"ratio ours semi-implicit (no plane) / scipy RK45: {results[('semi-implicit-euler', False)] / results[('scipy', 'RK45')]:.2f}")
    print(f"ratio semi-implicit / rk4 (with plane): {results[('semi-implicit-euler', True)] / results[('rk4', True)]:.2f}")
    print("# n-body force (one evaluation, O(n^2))")
    rng = np.random.default_rng(1)
    for nb in (64, 128, 256, 512, 1024, 2048):
        x = rng.normal(size=(nb, 3))
        m = np.ones(nb)
        reps = max(1, 20000 // nb)
        start = time.perf_counter()
        for _ in range(reps):
            forces.newtonian_gravity(x, m, 1.0, 1e-3)
        el = (time.perf_counter() - start) / reps
        print(f"n = {nb:5d}: {el * 1e3:8.3f} ms per evaluation, {el / (nb * nb) * 1e9:6.2f} ns per pair")
    print("# peak memory of the 100k run (rk4 with plane)")
    tracemalloc.start()
    run_ours(n, "rk4", 10, h, True)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"peak traced numpy/python allocation: {peak / 2**20:.1f} MiB; process max RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.1f} MiB")


if __name__ == "__main__":
    main()
