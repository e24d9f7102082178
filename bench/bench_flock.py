"""Flock benchmark (not a timed test): `python bench/bench_flock.py [counts...]`.

Cost per step of a flock (pipeline/dynamics/flock.py: cKDTree k-nearest neighbours,
steering, separation passes, containment) at 1k, 10k and 100k agents. The spawn box grows
with the count so the density (agents per m^3) stays the same: with a fixed k nearest
neighbours the work per agent is constant and the cost per step should grow about
linearly (n log n for the tree). Prints seconds per step and microseconds per agent-step.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

from motion.pipeline.dynamics.flock import FlockParams, flock_step, spawn
from motion.pipeline.scene.motion_schema import Flock

DENSITY = 8.0  # agents per m^3 at the start (mean spacing 0.5 m)


def bench(count: int, steps: int = 20, warm: int = 3) -> float:
    """Seconds per step (median of `steps` after `warm` unmeasured steps)."""
    side = (count / DENSITY) ** (1.0 / 3.0)
    spec = Flock(type="flock", count=count, seed=1, spawn_size=(side, side, side), speed=1.0,
                 separation=0.3, neighbour_radius=1.0, goal=(side, 0.0, 0.0),
                 bounds={"min": (-side, -side, -side), "max": (side, side, side)})
    p = FlockParams.from_spec(spec)
    x, v = spawn(p)
    for _ in range(warm):
        x, v = flock_step(p, x, v, [], p.step)
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        x, v = flock_step(p, x, v, [], p.step)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(counts: list[int]) -> None:
    print(f"CPU: {cpu_model()}; numpy {np.__version__}; one process")
    base = None
    for n in counts:
        s = bench(n, steps=10 if n >= 100_000 else 20)
        per = s / n * 1e6
        base = base or per
        print(f"{n:>8} agents: {s * 1e3:9.2f} ms/step  {per:6.2f} us/agent-step  (x{per / base:.2f} of the smallest per agent)")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [1_000, 10_000, 100_000])
