"""Our warm frame against the engine's own speed: Mitsuba's `path` on the same frame (issue 10).

    python bench/bench_vs_mitsuba.py [--quick] [--final] [--presets P,..] [--movers M,..] [--frames N] [--json FILE]

For each case the bench shot of bench_render.py (100k-triangle terrain, constant +
directional light, orbiting spheres) is rendered two ways, interleaved frame by frame in
one process:
  ours  - our worker's warm frame (`FrameRenderer.render`, stochastic motion blur: every
          sample at its own time in the shutter), after one cold frame;
  path  - Mitsuba's `path` integrator on the static twin of the same frame: the same
          records built by `mi.load_dict` (same resolution, spp, depth, filter, lights)
          with the movers frozen at the frame's time; only `mi.render` is timed.
Cases: 0, 1, 4 and 16 movers and a 10,000-particle spray, at the ci-smoke and preview
presets (and `--final`: 1080p x 256 spp, one warm frame, minutes on 2 cores); plus, at
preview with 4 movers, the same frame with motion blur off. Per case, the breakdown of one
warm frame from drjit's kernel history: the path kernel (ray casts, shading, sampling),
the film's kernels, other kernels, and the rest of the wall time (Python tracing,
parameter updates, readback).
"""

from __future__ import annotations

import argparse
import gc
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402
from bench_render import shot, terrain_ply  # noqa: E402

PRESETS = {"ci-smoke": ((64, 36), 4, 3), "preview": ((320, 180), 16, 4), "final": ((1920, 1080), 256, 8)}


def twin(renderer: Any, fi: Any, mi: Any) -> Any:
    """Mitsuba's `path` on the frame's static twin: the scalar fallback's records of the
    frame's time (`_full_scene_dict`: movers at their frame pose, particles as exact spheres
    in one `ellipsoids` shape)."""
    from motion.pipeline.render.poses.stacked import stack_frame

    return mi.load_dict(renderer._full_scene_dict(stack_frame(fi), None))


def breakdown(renderer: Any, fi: Any) -> dict[str, float]:
    """One warm frame split by drjit's kernel history (milliseconds)."""
    t0 = time.perf_counter()
    renderer.render(fi)
    wall = (time.perf_counter() - t0) * 1000
    kernels = [(int(h.get("size", 0)), float(h.get("execution_time", 0.0))) for h in renderer._last_history]
    lanes = max((size for size, _ in kernels), default=0)
    path_ms = sum(ms for size, ms in kernels if size == lanes)  # the megakernel: one lane per sample
    film_ms = sum(ms for size, ms in kernels if size != lanes)
    return {"wall_ms": wall, "path_kernel_ms": path_ms, "film_and_other_kernels_ms": film_ms, "python_and_rest_ms": wall - path_ms - film_ms}


def case(folder: Path, preset: str, movers: int, particles: int, frames: int, blur: str = "stochastic") -> dict[str, Any]:
    import drjit as dr
    import mitsuba as mi

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    res, spp, depth = PRESETS[preset]
    loaded = load_scene(shot(folder, movers=movers, particles=particles, blur=blur, res=res, spp=spp, depth=depth, last=frames + 2))
    inputs = evaluate_frames(loaded, list(range(frames + 2)))
    gc.collect()
    renderer = FrameRenderer(loaded)
    renderer.render(inputs[0])  # cold
    mi.render(twin(renderer, inputs[0], mi), spp=spp)  # the twin's kernels compiled too
    ours, path = [], []
    for fi in inputs[1:-1]:
        t0 = time.perf_counter()
        img, _ = renderer.render(fi)
        ours.append(time.perf_counter() - t0)
        scene = twin(renderer, fi, mi)
        t0 = time.perf_counter()
        ref = mi.render(scene, seed=fi.frame, spp=spp)
        dr.eval(ref)
        np.array(ref)
        path.append(time.perf_counter() - t0)
        del scene
    o, p = statistics.median(ours), statistics.median(path)
    return {"preset": preset, "movers": movers, "particles": particles, "blur": blur, "ours_s": o, "path_s": p, "ratio": o / p, "breakdown": breakdown(renderer, inputs[-1])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="ci-smoke and preview at 0 and 4 movers only")
    parser.add_argument("--final", action="store_true", help="also the final preset (1080p, 256 spp): minutes per frame")
    parser.add_argument("--presets", default="ci-smoke,preview", help="comma-separated presets for the mover and particle cases (default: ci-smoke,preview)")
    parser.add_argument("--frames", type=int, default=5, help="warm frames per case (median)")
    parser.add_argument("--movers", help="comma-separated mover counts, only those cases (default: 0,1,4,16, the particles and blur off)")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    args = parser.parse_args()
    from motion.pipeline import variant

    chosen = variant.activate("auto", quiet=True).variant
    cases: list[tuple[str, int, int, str]] = []
    presets = [p for p in args.presets.split(",") if p]
    unknown = [p for p in presets if p not in PRESETS or p == "final"]
    if unknown:
        parser.error(f"--presets takes ci-smoke and/or preview (the final preset is --final), not {', '.join(unknown)}")
    only = [int(m) for m in args.movers.split(",")] if args.movers else None
    for preset in presets:
        for movers in only or ((0, 4) if args.quick else (0, 1, 4, 16)):
            cases.append((preset, movers, 0, "stochastic"))
        if not args.quick and only is None:
            cases.append((preset, 0, 10_000, "stochastic"))
    if "preview" in presets and only is None:
        cases.append(("preview", 4, 0, "off"))
    if args.final:
        cases += [("final", 0, 0, "stochastic"), ("final", 4, 0, "stochastic")]
    print(f"# ours vs Mitsuba path: {cpu_model()}, {chosen}; median of {args.frames} warm frames, interleaved")
    print("\n| preset | movers | particles | blur | ours (s) | path static twin (s) | ours / path | path kernel (ms) | film + other kernels (ms) | Python + rest (ms) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        terrain_ply(folder / "terrain.ply")
        for preset, movers, particles, blur in cases:
            frames = 1 if preset == "final" else args.frames
            r = case(folder, preset, movers, particles, frames, blur)
            rows.append(r)
            b = r["breakdown"]
            print(
                f"| {preset} | {movers} | {particles} | {blur} | {r['ours_s']:.3f} | {r['path_s']:.3f} | {r['ratio']:.2f}x | "
                f"{b['path_kernel_ms']:.0f} | {b['film_and_other_kernels_ms']:.0f} | {b['python_and_rest_ms']:.0f} |",
                flush=True,
            )
    if "preview" in presets and only is None:
        blurred = next(r for r in rows if r["preset"] == "preview" and r["movers"] == 4 and r["blur"] == "stochastic")
        still = next(r for r in rows if r["preset"] == "preview" and r["movers"] == 4 and r["blur"] == "off")
        # each side divided by the twin measured beside it, so that machine noise between the
        # two cases cancels: (ours_blur / path) / (ours_off / path)
        print(f"\nstochastic motion blur at 4 movers vs blur off (preview, each against its own twin): {blurred['ratio'] / still['ratio']:.2f}x")
    if args.json:
        args.json.write_text(json.dumps({"cpu": cpu_model(), "variant": chosen, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
