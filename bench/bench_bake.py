"""Bake time of the example shots: the whole timeline's dynamics simulation plus the bake of
every frame, as `motion render` runs it before the first task (issue 16: the cannonball
under 1 s, the bouncing balls under 2 s). CPU seconds (process time), best of `--repeat`.

Run: python bench/bench_bake.py [SCENE ...] [--repeat N]

Before/after: put an older checkout's folders under a `motion` package on PYTHONPATH
(motion/pipeline -> OLD/pipeline, ...) and run this script with it and without it,
alternating, in one session; compare the ratios, not the absolute figures (a shared,
noisy machine)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ["cannonball", "bouncing-balls", "spinning-top"]


def bake_seconds(path: Path, repeat: int) -> tuple[float, float, int]:
    """(simulate s, bake s, steps) at their best of `repeat` runs, CPU time."""
    from motion.pipeline.bake import bake
    from motion.pipeline.scene import load_scene

    loaded = load_scene(path)
    frames = list(loaded.scene.timeline.timeline().frames)
    best_sim, best_bake, steps = float("inf"), float("inf"), 0
    for _ in range(repeat):
        from motion.pipeline.farm.frame_inputs import simulation_for

        t0 = time.process_time()
        sim = simulation_for(loaded, frames)
        t1 = time.process_time()
        bake(loaded, frames, sim)
        t2 = time.process_time()
        best_sim, best_bake = min(best_sim, t1 - t0), min(best_bake, t2 - t1)
        if sim is not None and sim.bodies is not None:
            steps = len(sim.bodies.times) - 1
    return best_sim, best_bake, steps


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"# {cpu_model()}; CPU seconds, best of {args.repeat}")
    for name in args.scenes:
        path = Path(name) if name.endswith(".yaml") else ROOT / "scenes" / f"{name}.yaml"
        sim, bk, steps = bake_seconds(path, args.repeat)
        per_step = f"{sim / steps * 1e3:.3f} ms/step over {steps} steps" if steps else "no rigid bodies"
        print(f"{path.stem:16s} simulate {sim:6.2f} s ({per_step}), bake {bk:5.2f} s, total {sim + bk:6.2f} s")


if __name__ == "__main__":
    main()
