"""Where a scene's frame time goes, in this process, on the variant `auto` picks (or --variant).

    python tools/profile_frames.py SCENE [--frames 0,48,95] [--resolution 128x72] [--spp 32] [--prof FILE] [--top 25]

One first-frame-cached FrameRenderer renders the frames in order, as a worker does. Per frame:
the setup (a cold build or a warm update) and render seconds, drjit's JIT kernels of the
render (how many, compiled or cache hits, their codegen, backend-compile and execution
milliseconds) and the traversal's movers (deforming meshes' included) and particle slots. With --prof, a cProfile of the whole
run is written there and its top functions by cumulative time are printed: the tool that
found why an example was 40x slower on CUDA than on LLVM (docs/rendering.md).
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import pstats
import sys
import time
from pathlib import Path
from typing import Any


def kernel_summary(history: list[dict[str, Any]]) -> dict[str, float]:
    """Counts and summed milliseconds of drjit's JIT kernels in `history`."""
    import drjit as dr

    jit = [h for h in history if h.get("type") == dr.KernelType.JIT]
    return {
        "kernels": len(jit),
        "compiled": sum(1 for h in jit if not h.get("cache_hit", False)),
        "codegen_ms": round(sum(float(h.get("codegen_time", 0.0)) for h in jit), 1),
        "backend_ms": round(sum(float(h.get("backend_time", 0.0)) for h in jit), 1),
        "exec_ms": round(sum(float(h.get("execution_time", 0.0)) for h in jit), 1),
        "ops": sum(int(h.get("operation_count", 0)) for h in jit),
    }


def main() -> int:
    """Render the frames and print where their time went."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", type=Path)
    parser.add_argument("--frames", default="0,1,2")
    parser.add_argument("--resolution", default="128x72")
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--variant", default="auto")
    parser.add_argument("--prof", type=Path, help="write a cProfile of the run here and print its top functions")
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args()

    from motion.pipeline import variant

    chosen = variant.activate(args.variant, quiet=True).variant
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.scene import load_scene

    width, height = (int(v) for v in args.resolution.lower().split("x"))
    overrides = {"render": {"resolution": [width, height], "spp": args.spp, "denoise": "off"}}
    frames = [int(f) for f in args.frames.split(",")]
    profiler = cProfile.Profile() if args.prof else None
    t0 = time.perf_counter()
    if profiler:
        profiler.enable()
    loaded = load_scene(args.scene, overrides=overrides)
    gc.collect()
    renderer = FrameRenderer(loaded)
    print(f"# {args.scene.name} on {chosen}: load {time.perf_counter() - t0:.2f} s; {width}x{height}, {args.spp} spp")
    for fi in evaluate_frames(loaded, frames):
        t1 = time.perf_counter()
        _, stats = renderer.render(fi, None)
        wall = time.perf_counter() - t1
        summary = kernel_summary(renderer._last_history)
        cache = renderer.cache
        world = cache.integrator.world if cache.scene is not None else None
        movers = f"{world.rigid} movers, {world.particles} particle slots" if world is not None else "no motion_path scene"
        print(f"frame {fi.frame}: wall {wall:.2f} s, setup {stats.setup_s:.2f} s, render {stats.render_s:.2f} s, cold {stats.cold}, "
              f"kernels {summary['kernels']} ({summary['compiled']} compiled): codegen {summary['codegen_ms']} ms, "
              f"backend {summary['backend_ms']} ms, exec {summary['exec_ms']} ms, {summary['ops']} ops; {movers}")
    if profiler:
        profiler.disable()
        profiler.dump_stats(str(args.prof))
        pstats.Stats(profiler, stream=sys.stdout).sort_stats("cumulative").print_stats(args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
