"""Contacts benchmark: penalty forces (several stiffnesses, each integrator) against impulses,
the comparison CG:PP 35.6.5.3 argues (docs/dynamics.md, "Penalty contacts").

  ball: a 1 kg sphere (r = 0.1 m) dropped from 0.5 m onto the ground plane, restitution
        0.8: the deepest penetration of the first contact, the first rebound's height
        against the analytic e^2 h0, and the energy drift of an elastic ball (e = 1)
        dropped from 0.01 m over 100 bounces (E_end / E0 - 1; 0 is exact);
  box:  a 1 kg 0.2 m cube dropped from 0.5 m onto one edge (turned 45 degrees about Z, so
        its centre lies over the edge), restitution 0.3, friction 0.5: by symmetry it
        has no angular velocity until it tips, so any before 0.15 s after the impact is
        spurious; and its deepest penetration (its own validation, by its contact modes,
        is marked where it differs from the ball's);
  cost: CPU seconds per simulated second of the ball's 100 bounces.

Penalty contacts are given by their contact time T (20, 5, 1.25 ms: k = m omega0^2); the
fixed step is 1 ms. A configuration that validation refuses (the step past the
integrator's stability bound for the contact, docs/dynamics.md) is still run here, with
the scene's checks bypassed, to show what the bound prevents; `blew up` is the stability
guard stopping it.  Run: python bench/bench_contacts.py [--quick]"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _common import cpu_model  # noqa: E402
from motion.pipeline.dynamics import simulate  # noqa: E402
from motion.pipeline.errors import SimulationError  # noqa: E402
from motion.pipeline.scene import load_scene  # noqa: E402
from motion.pipeline.scene.dynamics_schema import penalty_problems, penalty_warnings  # noqa: E402

INTEGRATORS = ["euler", "semi-implicit-euler", "midpoint", "heun", "rk4", "rk45"]
CONTACT_TIMES = [0.02, 0.005, 0.00125]
STEP = 0.001
G = 9.81


def _floor(friction: float) -> dict:
    return {"name": "floor", "shape": "rectangle", "width": 100, "height": 100, "transform": {"rotate": {"euler": [-90, 0, 0]}},
            "collider": {"restitution": 1.0, "friction": friction}}


def _scene(tmp: Path, body: dict, friction: float, last: int = 24) -> Path:
    doc = {"name": "bench", "timeline": {"fps": 24, "first": 0, "last": last}, "camera": {"position": [0, 1, 10], "look_at": [0, 0, 0]},
           "objects": [_floor(friction), body], "dynamics": {"integrator": "rk45", "step": STEP}}  # rk45: never refused
    path = tmp / "bench.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _run(tmp: Path, body: dict, integrator: str, t_end: float, friction: float = 0.0) -> tuple[object, float, str]:
    """Simulate with `integrator` (validation of that integrator bypassed, reported):
    (simulation or the error text, CPU seconds, refused by validation)."""
    loaded = load_scene(_scene(tmp, body, friction))
    dyn = loaded.scene.dynamics.model_copy(update={"integrator": integrator})
    loaded = replace(loaded, scene=loaded.scene.model_copy(update={"dynamics": dyn}))
    refused = "refused" if penalty_problems(loaded.scene) else "warns" if penalty_warnings(loaded.scene) else "ok"
    t0 = time.process_time()
    try:
        sim: object = simulate(loaded, t_end)
    except SimulationError as e:
        sim = "blew up" if "blew up" in str(e) else str(e)[:60]
    return sim, time.process_time() - t0, refused


def _ball(y: float, restitution: float, contact: dict) -> dict:
    return {"name": "ball", "shape": "sphere", "radius": 0.1, "transform": {"translate": [0, y, 0]},
            "motion": {"type": "dynamics", "mass": 1.0, "restitution": restitution, "friction": 0.0, **contact}}


def _box(contact: dict) -> dict:
    return {"name": "box", "shape": "cube", "size": 0.2, "transform": {"translate": [0, 0.5 + 0.1 * math.sqrt(2), 0], "rotate": {"euler": [0, 0, 45]}},
            "motion": {"type": "dynamics", "mass": 1.0, "restitution": 0.3, "friction": 0.5, **contact}}


def ball_figures(tmp: Path, integrator: str, contact: dict, bounces: int) -> dict:
    """Penetration (mm), first rebound vs e^2 h0 (%), energy drift over `bounces` elastic
    bounces, CPU s per simulated s."""
    out: dict = {}
    h0, e = 0.5, 0.8
    sim, _, refused = _run(tmp, _ball(0.1 + h0, e, contact), integrator, 2 * math.sqrt(2 * h0 / G) * (1 + e) + 0.05)
    out["refused"] = refused
    if isinstance(sim, str):
        out["status"] = sim
        return out
    y = sim.bodies.x[:, 0, 1]
    t = sim.bodies.times
    first = t < math.sqrt(2 * h0 / G) + 0.05
    out["depth_mm"] = max(0.0, 1e3 * (0.1 - y[first].min()))  # (impulses: never below the surface)
    after = t > math.sqrt(2 * h0 / G) + 0.05
    out["rebound_err"] = 100 * ((y[after].max() - 0.1) / (e * e * h0) - 1)
    # energy drift: an elastic ball dropped from h1 over `bounces` bounces
    h1 = 0.01
    period = 2 * math.sqrt(2 * h1 / G)
    t_end = math.sqrt(2 * h1 / G) + (bounces - 0.5) * period  # at the apex after the last bounce
    elastic = dict(contact)
    if "penalty" in elastic:
        elastic["penalty"] = {**elastic["penalty"], "restitution": 1.0}
    sim, cpu, _ = _run(tmp, _ball(0.1 + h1, 1.0, elastic), integrator, t_end)
    if isinstance(sim, str):
        out["drift"] = sim
        return out
    # the track's potential is zero at the start; resting on the floor is zero here
    energy = sim.bodies.kinetic + sim.bodies.potential + 1.0 * G * h1
    out["drift"] = energy[-1] / energy[0] - 1
    out["cost"] = cpu / t_end
    return out


def box_figures(tmp: Path, integrator: str, contact: dict) -> dict:
    """Max |w| (rad/s) before it could tip (0.15 s after the drop's impact) and the depth."""
    sim, _, refused = _run(tmp, _box(contact), integrator, math.sqrt(2 * 0.5 / G) + 0.15, friction=0.5)
    mark = " (refused)" if refused == "refused" else ""
    if isinstance(sim, str):
        return {"box": sim + mark}
    # the spin about Z from the track's orientations: |w_z| = 2 |d(q_z)/dt| / q_w... at small angles
    spin = float(np.abs(np.gradient(sim.bodies.q[:, 0, 3], sim.bodies.times) * 2 / np.maximum(np.abs(sim.bodies.q[:, 0, 0]), 0.5)).max())
    lowest = sim.bodies.x[:, 0, 1].min() - 0.1 * math.sqrt(2)
    return {"spin": f"{spin:.2g}{mark}", "box_depth_mm": f"{max(0.0, -1e3 * lowest):.3g}"}


def main() -> None:
    """Print the table (markdown)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 bounces instead of 100 (the default takes about a minute on 2 cores)")
    args = ap.parse_args()
    bounces = 10 if args.quick else 100
    print(f"CPU: {cpu_model()}; step {1e3 * STEP:g} ms; {bounces} elastic bounces for the drift")
    print("| contact | integrator | k (N/m) | validation | ball depth (mm) | rebound vs e^2 h0 | energy drift | box spin (rad/s) | box depth (mm) | CPU s / sim s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows = [("impulse", None, integ) for integ in ("semi-implicit-euler", "rk4")]
        rows += [("penalty", tc, integ) for tc in CONTACT_TIMES for integ in INTEGRATORS]
        for kind, tc, integ in rows:
            contact = {"contact": "impulse"} if tc is None else {"contact": "penalty", "penalty": {"contact_time": tc}}
            b = ball_figures(tmp, integ, contact, bounces)
            x = box_figures(tmp, integ, contact)
            k = "-" if tc is None else f"{(math.pi / tc) ** 2 / (1 - 0.071**2):.3g}"  # zeta of e = 0.8
            label = kind if tc is None else f"penalty T = {1e3 * tc:g} ms"

            def fmt(key: str, spec: str, src: dict = b) -> str:
                v = src.get(key, src.get("status", src.get("box", "-")))
                return format(v, spec) if isinstance(v, float) else str(v)

            print(f"| {label} | {integ} | {k} | {b.get('refused', '-')} | {fmt('depth_mm', '.3g')} | {fmt('rebound_err', '+.2f')}% | "
                  f"{fmt('drift', '+.2e')} | {fmt('spin', '.2g', x)} | {fmt('box_depth_mm', '.3g', x)} | {fmt('cost', '.3g')} |", flush=True)


if __name__ == "__main__":
    main()
