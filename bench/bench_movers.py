"""Motion blur that scales: N rigid movers against the same N objects standing still.

    python bench/bench_movers.py [--counts 1,10,100,1000] [--particles 100000] [--distinct] [--frames 3] [--res 320x180] [--spp 16] [--json FILE]
                                 [--cycles-python PY] [--images DIR]

The shot: N small spheres on a square grid under a constant light, each parented to an
empty that turns (a turntable generator), so every sphere orbits its own centre with
motion blur; its static twin is the same grid with nothing moving. Each case is one
`motion render` process (one worker, an empty cache root of its own, so the first frame
pays every first-frame cost: scene build, BVH, kernel compilation); the figures are the
run report's own per-frame seconds: the first frame, and the median of the warm ones.
Moving and static cases alternate in one run, so their ratio is measured side by side.
With --particles P, a spray of P particles (each a sphere on its baked path) against the
same particles frozen (`motion_blur: off`), and each case's peak memory (max RSS).

The peer: with `bpy` importable by --cycles-python (default $BENCH_CYCLES_PYTHON, else this
Python; Blender as a Python module, `pip install bpy` for Python 3.11, in an environment of
its own: it pins numpy < 2), Blender Cycles (CPU, the same threads as our one worker)
renders the same shot, read from the same YAML, beside ours: each case a fresh subprocess
of that Python (`read_factory_settings(use_empty=True)`, our Y-up turned to Blender's Z-up),
UV spheres (32 x 16, smooth) parented to empties keyed to turn at the turntable's rate
(linear keys), the same camera, constant world, diffuse colours, shutter (angle / 360,
centred), 16 samples without denoiser or adaptive sampling, max bounces = max_depth - 2,
persistent data on; the time of each frame's `bpy.ops.render.render()`, first and median
warm. Without bpy: a one-line note, and the table as before. --images DIR keeps frame 1
of every case (ours and Cycles', EXR) to compare them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402
from _cycles import blender, cycles_scene, diffuse  # noqa: E402

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


def run_case(folder: Path, count: int, moving: bool, frames: int, res: tuple[int, int], spp: int, particles: bool = False, distinct: bool = False,
             images: Path | None = None) -> dict[str, Any]:
    """One `motion render` in a fresh process and cache root; the report's frame times and
    the process's peak memory (with `images`, frame 1's image copied there)."""
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
    if images is not None and len(rows) > 1 and rows[1].get("path"):
        images.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(rows[1]["path"], images / f"ours-{case.name}-frame1{Path(rows[1]['path']).suffix}")
    return {"first": seconds[0], "warm": statistics.median(seconds[1:]) if len(seconds) > 1 else float("nan"), "max_rss_mb": rss[-1] / 1024 if rss else float("nan")}


# --- Cycles (the peer; optional) ---------------------------------------------------------


def cycles_spec(text: str, threads: int) -> dict[str, Any]:
    """What the Cycles worker needs, read from the shot's own YAML (so both render one
    shot): timeline, camera, world, materials, the ground, the pivots (turntable rate, 0
    when still) and their balls, render settings; in our Y-up coordinates."""
    import yaml  # our environment's; the worker (bpy's Python) reads only the JSON

    d = yaml.safe_load(text)
    cam, render = d["camera"], d["render"]
    (light,) = d["lights"]
    assert light["type"] == "constant" and cam.get("fov_axis", "x") == "x" and cam.get("up", [0, 1, 0]) == [0, 1, 0]
    shutter = cam.get("shutter", {})
    assert shutter.get("position", "center") == "center"
    pivots, balls, ground = [], [], None
    for o in d["objects"]:
        if o["shape"] == "rectangle":
            assert o["transform"] == {"rotate": {"euler": [-90, 0, 0]}}  # the XZ plane, normal +Y
            ground = {"width": o["width"], "height": o["height"], "material": o["material"]}
        elif o["shape"] == "empty":
            gens = o.get("motion", {}).get("generators", [])
            assert all(g["type"] == "turntable" and g.get("axis", [0, 1, 0]) == [0, 1, 0] for g in gens) and len(gens) <= 1
            pivots.append({"name": o["name"], "translate": o["transform"]["translate"],
                           "rate": float(gens[0].get("rate", 360.0)) if gens else 0.0, "phase": float(gens[0].get("phase", 0.0)) if gens else 0.0})
        else:
            assert o["shape"] == "sphere"
            balls.append({"name": o["name"], "radius": o["radius"], "material": o["material"], "parent": o["parent"], "translate": o["transform"]["translate"]})
    return {
        "fps": d["timeline"]["fps"], "first": d["timeline"]["first"], "last": d["timeline"]["last"],
        "camera": {"position": cam["position"], "look_at": cam["look_at"], "fov": cam["fov"], "shutter": shutter.get("angle", 180.0) / 360.0},
        "world": light["radiance"], "materials": {m["name"]: m["color"] for m in d["materials"]}, "ground": ground, "pivots": pivots, "balls": balls,
        "resolution": render["resolution"], "spp": render["spp"], "max_bounces": render["max_depth"] - 2, "threads": threads,
    }


def cycles_worker(spec_file: Path) -> None:
    """Run inside a Python with `bpy`: build the spec's shot in Cycles, render its frames in
    order (persistent data: frames after the first are warm), time each frame's
    `bpy.ops.render.render()`; write the times (and frame 1's EXR, when asked) beside the spec."""
    import time  # noqa: I001 (bpy first: bmesh and mathutils are Blender's, there only once bpy is imported)

    import bpy
    import bmesh
    import mathutils

    spec = json.loads(spec_file.read_text())
    fps = spec["fps"]

    scene = cycles_scene(spec["threads"], spec["resolution"], fps, spec["camera"]["shutter"], spec["max_bounces"])  # shutter: angle / 360 of a frame
    # max_bounces: our max_depth counts path segments, camera + direct = 2
    scene.frame_start, scene.frame_end = spec["first"], spec["last"]
    scene.render.motion_blur_position = "CENTER"  # centred on the frame's time
    scene.cycles.samples = spec["spp"]
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.min_light_bounces = spec["max_bounces"]  # no Russian roulette before it (ours: rr_depth 5 > max_depth)
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = float(spec["world"])
    scene.world = world

    materials = {name: diffuse(name, rgb) for name, rgb in spec["materials"].items()}

    g = spec["ground"]
    w, h = g["width"] / 2, g["height"] / 2
    mesh = bpy.data.meshes.new("ground")
    mesh.from_pydata([(-w, -h, 0.0), (w, -h, 0.0), (w, h, 0.0), (-w, h, 0.0)], [], [(0, 1, 2, 3)])
    mesh.materials.append(materials[g["material"]])
    scene.collection.objects.link(bpy.data.objects.new("ground", mesh))

    def fcurves(obj: Any) -> Any:  # an object's F-curves: in its action's slot (Blender 4.4+ layered actions), else the action's own
        action = obj.animation_data.action
        if hasattr(obj.animation_data, "action_slot"):
            from bpy_extras import anim_utils

            return anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot).fcurves
        return action.fcurves

    first, last = spec["first"], spec["last"]
    pivots = {}
    for p in spec["pivots"]:
        empty = bpy.data.objects.new(p["name"], None)
        empty.location = blender(p["translate"])
        if p["rate"]:  # about our +Y, Blender's +Z: phase + rate * t degrees, keyed linearly past both ends of the shutter
            for f in (first - 1, last + 1):
                empty.rotation_euler = (0.0, 0.0, math.radians(p["phase"] + p["rate"] * f / fps))
                empty.keyframe_insert("rotation_euler", index=2, frame=f)
            for fcurve in fcurves(empty):
                for key in fcurve.keyframe_points:
                    key.interpolation = "LINEAR"
        scene.collection.objects.link(empty)
        pivots[p["name"]] = empty
    spheres: dict[tuple[float, str], Any] = {}  # one mesh per radius and material: the same shape is instanced, as Blender's linked duplicates are
    for b in spec["balls"]:
        key = (b["radius"], b["material"])
        if key not in spheres:
            bm = bmesh.new()
            bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=b["radius"])
            for face in bm.faces:
                face.smooth = True
            spheres[key] = bpy.data.meshes.new(f"sphere{len(spheres)}")
            bm.to_mesh(spheres[key])
            bm.free()
            spheres[key].materials.append(materials[b["material"]])
        ball = bpy.data.objects.new(b["name"], spheres[key])
        ball.parent = pivots[b["parent"]]
        ball.location = blender(b["translate"])
        scene.collection.objects.link(ball)

    c = spec["camera"]
    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "HORIZONTAL"  # our fov_axis x
    cam.angle = math.radians(c["fov"])
    cam.clip_start, cam.clip_end = 0.01, 10000.0
    cam_obj = bpy.data.objects.new("camera", cam)
    cam_obj.location = blender(c["position"])
    cam_obj.rotation_mode = "QUATERNION"
    cam_obj.rotation_quaternion = (mathutils.Vector(blender(c["look_at"])) - cam_obj.location).to_track_quat("-Z", "Y")
    scene.collection.objects.link(cam_obj)
    scene.camera = cam_obj

    seconds = []
    for frame in range(first, last + 1):
        scene.frame_set(frame)
        t0 = time.perf_counter()
        bpy.ops.render.render()
        seconds.append(time.perf_counter() - t0)
        if spec.get("image") and frame == first + 1:
            bpy.data.images["Render Result"].save_render(spec["image"], scene=scene)
    out = {"seconds": seconds, "version": bpy.app.version_string}
    (spec_file.parent / "cycles-times.json").write_text(json.dumps(out))


def has_bpy(python: str) -> bool:
    """Whether `python` runs and imports bpy."""
    try:
        return subprocess.run([python, "-c", "import bpy"], capture_output=True, check=False).returncode == 0
    except OSError:
        return False


def run_cycles(folder: Path, count: int, moving: bool, frames: int, res: tuple[int, int], spp: int, python: str, threads: int, distinct: bool = False,
               images: Path | None = None) -> dict[str, Any]:
    """One Cycles case in a fresh subprocess of `python` (a Python with bpy): the first frame
    and the median warm frame of `bpy.ops.render.render()`."""
    case = folder / f"cycles-{count}-{'moving' if moving else 'static'}{'-distinct' if distinct else ''}"
    case.mkdir(parents=True, exist_ok=True)
    spec = cycles_spec(shot(count, moving, frames, res, spp, distinct=distinct), threads)
    if images is not None and frames > 1:
        images.mkdir(parents=True, exist_ok=True)
        spec["image"] = str((images / f"cycles-movers-{count}-{'moving' if moving else 'static'}{'-distinct' if distinct else ''}-frame1.exr").resolve())
    (case / "spec.json").write_text(json.dumps(spec))
    proc = subprocess.run([python, str(Path(__file__).resolve()), "--cycles-worker", str(case / "spec.json")], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{case.name}: exit {proc.returncode}\n{(proc.stdout + proc.stderr)[-2000:]}")
    out = json.loads((case / "cycles-times.json").read_text())
    seconds = out["seconds"]
    return {"first": seconds[0], "warm": statistics.median(seconds[1:]) if len(seconds) > 1 else float("nan"), "version": out["version"]}


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
    ap.add_argument("--cycles-python", default=os.environ.get("BENCH_CYCLES_PYTHON", sys.executable),
                    help="a Python with bpy: Blender Cycles renders the same shot beside ours (default: $BENCH_CYCLES_PYTHON, else this one; skipped without bpy)")
    ap.add_argument("--images", type=Path, help="keep frame 1 of every movers case here (ours and Cycles', EXR)")
    ap.add_argument("--cycles-worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cycles_worker:
        cycles_worker(args.cycles_worker)
        return
    res = tuple(int(v) for v in args.res.split("x"))
    counts = [int(c) for c in args.counts.split(",")]
    have_cycles = has_bpy(args.cycles_python)
    if not have_cycles:
        print(f"# bpy not importable by {args.cycles_python}: Cycles skipped (pip install bpy, Python 3.11, in its own environment; --cycles-python or $BENCH_CYCLES_PYTHON)")
    threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)  # one worker's drjit threads (farm/sizing.threads_per_worker(1))
    print(f"# bench_movers: {res[0]}x{res[1]}, {args.spp} spp, {args.frames} frames, 1 worker, {'every sphere its own radius' if args.distinct else 'one radius'}; "
          f"CPU: {cpu_model()}, {os.cpu_count()} cores")
    if have_cycles:
        print("| N | first frame, moving | first frame, static | warm moving | warm static | warm moving / static "
              "| Cycles first, moving | Cycles first, static | Cycles warm moving | Cycles warm static | Cycles warm moving / static | ours / Cycles, warm moving |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    else:
        print("| N | first frame, moving | first frame, static | warm moving | warm static | warm moving / static |")
        print("|---|---|---|---|---|---|")
    results = []
    version = None
    with tempfile.TemporaryDirectory(prefix="bench-movers-") as tmp:
        for n in counts:
            moving = run_case(Path(tmp), n, True, args.frames, res, args.spp, distinct=args.distinct, images=args.images)  # type: ignore[arg-type]
            still = run_case(Path(tmp), n, False, args.frames, res, args.spp, distinct=args.distinct, images=args.images)  # type: ignore[arg-type]
            ratio = moving["warm"] / still["warm"]
            row: dict[str, Any] = {"n": n, "moving": moving, "static": still, "warm_ratio": ratio}
            line = f"| {n} | {moving['first']:.2f} s | {still['first']:.2f} s | {moving['warm']:.3f} s | {still['warm']:.3f} s | {ratio:.2f}x |"
            if have_cycles:
                c_moving = run_cycles(Path(tmp), n, True, args.frames, res, args.spp, args.cycles_python, threads, args.distinct, args.images)  # type: ignore[arg-type]
                c_still = run_cycles(Path(tmp), n, False, args.frames, res, args.spp, args.cycles_python, threads, args.distinct, args.images)  # type: ignore[arg-type]
                version = c_moving.pop("version")
                c_still.pop("version")
                c_ratio = c_moving["warm"] / c_still["warm"]
                versus = moving["warm"] / c_moving["warm"]
                row["cycles"] = {"moving": c_moving, "static": c_still, "warm_ratio": c_ratio}
                row["ours_vs_cycles_warm_moving"] = versus
                line += (f" {c_moving['first']:.2f} s | {c_still['first']:.2f} s | {c_moving['warm']:.3f} s | {c_still['warm']:.3f} s | {c_ratio:.2f}x | {versus:.2f}x |")
            results.append(row)
            print(line, flush=True)
        if args.particles:
            blur = run_case(Path(tmp), args.particles, True, args.frames, res, args.spp, particles=True)  # type: ignore[arg-type]
            frozen = run_case(Path(tmp), args.particles, False, args.frames, res, args.spp, particles=True)  # type: ignore[arg-type]
            ratio = blur["warm"] / frozen["warm"]
            results.append({"particles": args.particles, "blur": blur, "frozen": frozen, "warm_ratio": ratio})
            print(f"\n{args.particles} particles: warm frame blurred {blur['warm']:.3f} s, frozen {frozen['warm']:.3f} s: {ratio:.2f}x; "
                  f"first frame {blur['first']:.2f} s / {frozen['first']:.2f} s; max RSS {blur['max_rss_mb']:.0f} / {frozen['max_rss_mb']:.0f} MB", flush=True)
    if have_cycles:
        print(f"# Cycles {version} (CPU, {threads} threads, the same shot; persistent data): `bpy.ops.render.render()` per frame; CPU: {cpu_model()}")
    if args.json_out:
        out: dict[str, Any] = {"cpu": cpu_model(), "results": results}
        if have_cycles:
            out["cycles"] = {"python": args.cycles_python, "version": version, "threads": threads}
        Path(args.json_out).write_text(json.dumps(out, indent=1))

if __name__ == "__main__":
    main()
