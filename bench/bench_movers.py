"""Motion blur that scales: N rigid movers against the same N objects standing still.

    python bench/bench_movers.py [--counts 1,10,100,1000] [--particles 100000] [--distinct] [--frames 3] [--res 320x180] [--spp 16] [--json FILE]

The shot: N small spheres on a square grid under a constant light, each parented to an
empty that turns (a turntable generator), so every sphere orbits its own centre with
motion blur; its static twin is the same grid with nothing moving. Each case is one
`motion render` process (one worker, an empty cache root of its own, so the first frame
pays every first-frame cost: scene build, BVH, kernel compilation); the figures are the
run report's own per-frame seconds: the first frame, and the median of the warm ones.
Moving and static cases alternate in one run, so their ratio is measured side by side.
With --particles P, a spray of P particles (each a sphere on its baked path) against the
same particles frozen (`motion_blur: off`), and each case's peak memory (max RSS).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def shot(count: int, moving: bool, frames: int, res: tuple[int, int], spp: int, particles: int = 0, distinct: bool = False) -> str:
    """The scene YAML: `count` spheres on a grid, orbiting (moving) or still; with
    `distinct`, each sphere's radius differs a little from every other's (no two movers'
    shapes are the same: each keeps a cell of the atlas of its own, as debris of unique
    pieces does), else all share one radius (one cell, render/kernel/atlas.py)."""
    side = max(1, math.ceil(math.sqrt(count)))
    spacing = 8.0 / side
    radius = spacing * 0.3
    lines = [
        f"name: movers-{count}-{'moving' if moving else 'static'}",
        f"timeline: {{fps: 24, first: 0, last: {frames - 1}}}",
        "camera: {position: [0, 9, 7], look_at: [0, 0, 0], fov: 50, shutter: {angle: 180, position: center}}",
        "lights: [{type: constant, radiance: 1.0}]",
        "materials: [{name: paint, type: diffuse, color: [0.8, 0.3, 0.2]}, {name: ground, type: diffuse, color: [0.5, 0.5, 0.5]}]",
        "objects:",
        "  - {name: ground, shape: rectangle, width: 12, height: 12, material: ground, transform: {rotate: {euler: [-90, 0, 0]}}}",
    ]
    for k in range(count):
        x = (k % side - (side - 1) / 2) * spacing
        z = (k // side - (side - 1) / 2) * spacing
        motion = f", motion: {{type: procedural, generators: [{{type: turntable, axis: [0, 1, 0], rate: {720 + 7 * (k % 13)}}}]}}" if moving else ""
        lines.append(f"  - {{name: pivot{k}, shape: empty, transform: {{translate: [{x:.4f}, {radius:.4f}, {z:.4f}]}}{motion}}}")
        size = radius * (0.6 - 0.2 * k / max(1, count)) if distinct else radius * 0.6
        lines.append(f"  - {{name: ball{k}, shape: sphere, radius: {size:.6f}, material: paint, parent: pivot{k}, transform: {{translate: [{radius * 0.5:.4f}, 0, 0]}}}}")
    lines.append(f"render: {{resolution: [{res[0]}, {res[1]}], spp: {spp}, max_depth: 4}}")
    return "\n".join(lines) + "\n"


def spray(count: int, blur: bool, frames: int, res: tuple[int, int], spp: int) -> str:
    """The scene YAML: `count` particles born over the first second, fast, over a ground;
    rendered at the end of that second, with motion blur or frozen."""
    return "\n".join([
        f"name: spray-{count}-{'blur' if blur else 'frozen'}",
        f"timeline: {{fps: 24, first: 0, last: {24 + frames - 1}}}",
        "camera: {position: [0, 4, 12], look_at: [0, 2, 0], fov: 45, shutter: {angle: 180}}",
        "lights: [{type: constant, radiance: 1.0}]",
        "materials: [{name: water, type: diffuse, color: [0.6, 0.7, 0.9]}, {name: ground, type: diffuse, color: [0.5, 0.5, 0.5]}]",
        "objects:",
        "  - {name: ground, shape: rectangle, width: 30, height: 30, material: ground, transform: {rotate: {euler: [-90, 0, 0]}}}",
        f"  - {{name: spray, shape: particles, radius: 0.02, material: water, emitter: {{rate: {count}, start: 0, stop: 1, lifetime: 10, max_count: {count}, position: [0, 0.2, 0], size: [0.5, 0.1, 0.5], speed: 12, speed_spread: 3, spread: 25}}}}",
        f"render: {{resolution: [{res[0]}, {res[1]}], spp: {spp}, max_depth: 4, motion_blur: {'stochastic' if blur else 'off'}}}",
    ]) + "\n"


def run_case(folder: Path, count: int, moving: bool, frames: int, res: tuple[int, int], spp: int, particles: bool = False, distinct: bool = False) -> dict[str, Any]:
    """One `motion render` in a fresh process and cache root; the report's frame times and
    the process's peak memory."""
    case = folder / f"{'spray' if particles else 'movers'}-{count}-{'moving' if moving else 'static'}{'-distinct' if distinct else ''}"
    case.mkdir(parents=True, exist_ok=True)
    scene = case / "shot.yaml"
    scene.write_text(spray(count, moving, frames, res, spp) if particles else shot(count, moving, frames, res, spp, distinct=distinct))
    env = {**os.environ, "MOTION_CACHE_DIR": str(case / "cache"), "MOTION_EXECUTOR": "local"}
    env.pop("DRJIT_CACHE_DIR", None)
    out = case / "out"
    frames_arg = ["--frames", f"24-{24 + frames - 1}"] if particles else []
    timer = ["/usr/bin/time", "-f", "MAXRSS %M"] if Path("/usr/bin/time").exists() else []  # GNU time: the peak memory
    proc = subprocess.run([*timer, sys.executable, "-m", "motion.cli.main", "-q", "render", str(scene), "-o", str(out), "--workers", "1",
                           "--json", "--no-progress", *frames_arg], capture_output=True, text=True, env=env, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"{case.name}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    report = json.loads((out / "render-report.json").read_text())
    rows = sorted(report["frames"], key=lambda r: r["frame"])
    seconds = [float(r["setup_s"]) + float(r["render_s"]) for r in rows]
    rss = [int(line.split()[1]) for line in proc.stderr.splitlines() if line.startswith("MAXRSS ")]
    return {"first": seconds[0], "warm": statistics.median(seconds[1:]) if len(seconds) > 1 else float("nan"), "max_rss_mb": rss[-1] / 1024 if rss else float("nan")}


def main() -> None:
    """Run the cases, print the table (and --json)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="1,10,100,1000")
    ap.add_argument("--particles", type=int, default=0, help="also a spray of this many particles, blurred against frozen")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--res", default="320x180")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--distinct", action="store_true", help="every sphere of its own radius: no two movers share an atlas cell (debris of unique pieces)")
    ap.add_argument("--json", dest="json_out")
    args = ap.parse_args()
    res = tuple(int(v) for v in args.res.split("x"))
    counts = [int(c) for c in args.counts.split(",")]
    print(f"# bench_movers: {res[0]}x{res[1]}, {args.spp} spp, {args.frames} frames, 1 worker, {'every sphere its own radius' if args.distinct else 'one radius'}; "
          f"CPU: {cpu_model()}, {os.cpu_count()} cores")
    print("| N | first frame, moving | first frame, static | warm moving | warm static | warm moving / static |")
    print("|---|---|---|---|---|---|")
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-movers-") as tmp:
        for n in counts:
            moving = run_case(Path(tmp), n, True, args.frames, res, args.spp, distinct=args.distinct)  # type: ignore[arg-type]
            still = run_case(Path(tmp), n, False, args.frames, res, args.spp, distinct=args.distinct)  # type: ignore[arg-type]
            ratio = moving["warm"] / still["warm"]
            results.append({"n": n, "moving": moving, "static": still, "warm_ratio": ratio})
            print(f"| {n} | {moving['first']:.2f} s | {still['first']:.2f} s | {moving['warm']:.3f} s | {still['warm']:.3f} s | {ratio:.2f}x |", flush=True)
        if args.particles:
            blur = run_case(Path(tmp), args.particles, True, args.frames, res, args.spp, particles=True)  # type: ignore[arg-type]
            frozen = run_case(Path(tmp), args.particles, False, args.frames, res, args.spp, particles=True)  # type: ignore[arg-type]
            ratio = blur["warm"] / frozen["warm"]
            results.append({"particles": args.particles, "blur": blur, "frozen": frozen, "warm_ratio": ratio})
            print(f"\n{args.particles} particles: warm frame blurred {blur['warm']:.3f} s, frozen {frozen['warm']:.3f} s: {ratio:.2f}x; "
                  f"first frame {blur['first']:.2f} s / {frozen['first']:.2f} s; max RSS {blur['max_rss_mb']:.0f} / {frozen['max_rss_mb']:.0f} MB", flush=True)
    if args.json_out:
        Path(args.json_out).write_text(json.dumps({"cpu": cpu_model(), "results": results}, indent=1))


if __name__ == "__main__":
    main()
