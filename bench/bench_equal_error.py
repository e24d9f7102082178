"""Time to equal error: our warm frame against Blender Cycles at the same relative MSE (issue 27).

    python bench/bench_equal_error.py [--spp 1,2,4,...,256] [--ref-spp 1024] [--shots bench,walk-cycle]
                                      [--denoise] [--no-cycles] [--cycles-python PY] [--json FILE]

Each shot is rendered by our worker (`FrameRenderer`, warm: after one cold frame, stochastic
motion blur) at every sample count of `--spp`, timed (render only, and the OIDN denoise with
`--denoise`, with the denoiser warm too: a worker makes OIDN's filter at its first frame),
and scored by relative MSE, mean((x - ref)^2 / (ref^2 + 0.01)), against our own
render of the same frame at `--ref-spp`. The time to reach each error level is interpolated
in log-log between the two counts that bracket it. With `bpy` importable by `--cycles-python`
(default: this Python, or $BENCH_CYCLES_PYTHON; Blender as a Python module, `pip install bpy`
for Python 3.11: optional, not a dependency of motion; bpy 5.0.1 pins numpy < 2, so give it
an environment of its own, e.g. `python3.11 -m venv .venv/cycles && .venv/cycles/bin/pip
install bpy`) the bench shot is built in Cycles from Python, in that subprocess (same terrain, balls posed by our own motion evaluation at sub-frame keys,
sky, sun, camera, 180-degree shutter, CPU, the same threads) and measured the same way against
Cycles' own reference; the ratio ours / Cycles is printed with the CPU's name.

Shots: `bench` - the 100k-triangle terrain of bench_render.py with 4 orbiting diffuse balls,
constant sky 0.4 + sun 2.5, 320x180, max_depth 4; `lamps` - the same with four point lamps
flying over the terrain (moving lights; ours only); `walk-cycle` - scenes/walk-cycle.yaml
(ours only: its rig is not rebuilt in Cycles).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402
from _cycles import blender, cycles_scene, diffuse  # noqa: E402
from bench_render import shot, terrain_ply  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
LEVELS = (5e-4, 3e-4, 1e-4, 7e-5, 5e-5)
FRAME = 5  # the frame measured (a warm frame: frame 4 renders cold first)
THREADS = int(os.environ.get("BENCH_THREADS", "2"))
LAMPS = int(os.environ.get("BENCH_LAMPS", "4"))  # point lamps of the `lamps` shot: 4, or a multiple of 4


def rel_mse(image: np.ndarray, reference: np.ndarray) -> float:
    """Relative MSE over RGB: mean((x - ref)^2 / (ref^2 + 0.01))."""
    x, r = image[..., :3].astype(np.float64), reference[..., :3].astype(np.float64)
    return float(np.mean((x - r) ** 2 / (r**2 + 1e-2)))


def time_to_error(points: list[tuple[float, float]], level: float) -> float | None:
    """Seconds to reach relMSE `level`, interpolated in log-log between the two measured
    (seconds, relMSE) points that bracket it; None outside the measured range."""
    pts = sorted(points)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 >= level >= e1 and e0 > e1:
            a = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + a * (math.log(t1) - math.log(t0)))
        if e0 == level:
            return t0
    return None


def bench_shot(folder: Path, denoise: bool) -> Path:
    """The bench shot with diffuse balls (the issue's frame)."""
    path = shot(folder, 4, res=(320, 180), spp=16, depth=4, last=12)
    text = path.read_text().replace("{name: paint, type: plastic, color: [0.7, 0.2, 0.1], roughness: 0.3}", "{name: paint, type: diffuse, color: [0.7, 0.2, 0.1]}")
    text = text.replace("camera: {position: [0, 4, 14], look_at: [0, 0.5, 0], fov: 50}", "camera: {position: [0, 4, 14], look_at: [0, 0.5, 0], fov: 50, shutter: {angle: 180}}")
    if denoise:
        text = text.replace("motion_blur: stochastic", "motion_blur: stochastic, denoise: oidn")
    terrain_ply(folder / "terrain.ply")
    path.write_text(text)
    return path


def lamps_shot(folder: Path, denoise: bool) -> Path:
    """The bench shot with four point lamps flying 2.5 m over the terrain (moving lights:
    posed at each path's time; chosen with the sun by contribution at each vertex)."""
    path = bench_shot(folder, denoise)
    keyed = "{{type: point, position: [{x}, 2.5, {z}], intensity: 6, motion: {{type: keyframes, interpolation: linear, channels: {{translate: {{keys: [{{time: 0, value: [{x}, 2.5, {z}]}}, {{time: 1, value: [{x2}, 2.5, {z}]}}]}}}}}}}}"
    spots = [(-6, -3), (-3, 2), (1, -2), (3, 3)] if LAMPS == 4 else [(-7 + 14 * (i % 4) / 3, -4 + 8 * (i // 4) / max(1, LAMPS // 4 - 1)) for i in range(LAMPS)]
    lamps = ", ".join(keyed.format(x=x, z=z, x2=x + 4) for x, z in spots)
    text = path.read_text()
    sun = "{type: directional, direction: [-0.4, -1, -0.3], irradiance: 2.5}]"
    assert sun in text
    path.write_text(text.replace(sun, sun[:-1] + ", " + lamps + "]"))
    return path


def walk_shot(folder: Path, denoise: bool) -> Path:
    """scenes/walk-cycle.yaml (copied beside its assets, with the denoiser when asked)."""
    text = (ROOT / "scenes" / "walk-cycle.yaml").read_text()
    if denoise:
        text = text.replace("render: {resolution: [480, 270], spp: 32, max_depth: 4}", "render: {resolution: [480, 270], spp: 32, max_depth: 4, denoise: oidn}")
    path = folder / "walk-cycle.yaml"
    path.write_text(text)
    return path


def ours(path: Path, spps: list[int], ref_spp: int, denoise: bool) -> dict[str, Any]:
    """Our warm frame at each count: seconds (best of 2), relMSE, and denoised figures."""
    from motion.pipeline import variant
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.scene import load_scene

    variant.activate("auto", quiet=True)
    import drjit as dr

    dr.set_thread_count(THREADS)
    loaded = load_scene(path)
    cold_fi, fi = evaluate_frames(loaded, [FRAME - 1, FRAME])
    renderer = FrameRenderer(loaded)
    renderer.render(cold_fi)
    # the reference with its own seed: no sample shared with the counts it judges
    settings = renderer.settings
    renderer.settings = settings.model_copy(update={"seed": settings.seed + 7919})
    renderer.spp = ref_spp
    reference, ref_aovs, _ = renderer.render_layers(fi)
    renderer.settings = settings
    if denoise:
        from motion.pipeline.render.output.denoise import denoise_frame

        denoise_frame(reference, ref_aovs)  # a worker's first denoise makes OIDN's filter: warm, as the frame is
    rows = []
    for spp in spps:
        renderer.spp = spp
        renderer.render(fi)  # compiles this count's film kernels (a job keeps one count)
        best = math.inf
        for _ in range(2):
            image, aovs, stats = renderer.render_layers(fi)
            best = min(best, stats.render_s)
        row = {"spp": spp, "seconds": best, "rel_mse": rel_mse(image, reference)}
        if denoise:
            from motion.pipeline.render.output.denoise import denoise_frame

            t0 = time.perf_counter()
            clean, _, _ = denoise_frame(image, aovs)
            row["denoise_s"] = time.perf_counter() - t0
            row["denoised_rel_mse"] = rel_mse(clean, reference)
        rows.append(row)
        print(f"  ours   {spp:4d} spp  {best:7.3f} s  relMSE {row['rel_mse']:.3e}" + (f"  denoised {row['denoised_rel_mse']:.3e} (+{row['denoise_s']:.2f} s)" if denoise else ""), flush=True)
    return {"rows": rows, "ref_spp": ref_spp, "reference_mean": float(reference[..., :3].mean())}


# --- Cycles (optional) -------------------------------------------------------------------


def cycles_spec(path: Path) -> dict[str, Any]:
    """What the Cycles worker needs: the balls' world positions at 17 times across the
    frame's shutter (our own motion evaluation) and the frame's time."""
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.motion import evaluate
    from motion.pipeline.scene import load_scene

    loaded = load_scene(path)
    (fi,) = evaluate_frames(loaded, [FRAME])
    times = np.linspace(fi.shutter[0], fi.shutter[1], 17)
    motion = evaluate(loaded, times)
    balls = {name: motion.objects[name].translation.tolist() for name in sorted(motion.objects) if name.startswith("ball")}
    return {"frame": FRAME, "fps": 24, "times": times.tolist(), "balls": balls, "threads": THREADS}


def cycles_worker(spec_file: Path) -> None:
    """Run inside a Python with `bpy`: build the bench shot in Cycles, render every count
    of the spec (best of 2, warm: persistent data) and the reference; write EXRs and the
    timings beside the spec."""
    import bpy
    import mathutils

    spec = json.loads(spec_file.read_text())
    out_dir = spec_file.parent

    fps = spec["fps"]
    # 180 degrees, centred on the frame; max bounces 3 for our max_depth 4 (the camera
    # segment + 3 bounces; bench_movers.py gives 2, which gives the same picture here)
    scene = cycles_scene(spec["threads"], (320, 180), fps, 0.5, 3)
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.4, 0.4, 0.4, 1.0)
    scene.world = world
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 2.5
    sun.angle = 0.0
    sun_obj = bpy.data.objects.new("sun", sun)
    sun_obj.rotation_mode = "QUATERNION"
    sun_obj.rotation_quaternion = mathutils.Vector(blender([-0.4, -1.0, -0.3])).normalized().to_track_quat("-Z", "Y")
    scene.collection.objects.link(sun_obj)

    # the terrain grid of bench_render.terrain_ply
    n = 224
    x, z = np.meshgrid(np.linspace(-20, 20, n), np.linspace(-20, 20, n))
    y = 0.3 * np.sin(x * 0.7) * np.cos(z * 0.5) + 0.1 * np.sin(3 * x + z)
    verts = [blender(v) for v in np.column_stack([x.ravel(), y.ravel(), z.ravel()])]
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n, i.ravel() + n + 1
    mesh = bpy.data.meshes.new("terrain")
    mesh.from_pydata(verts, [], np.concatenate([np.column_stack([a, c, b]), np.column_stack([b, c, d])]).tolist())
    ground = bpy.data.objects.new("terrain", mesh)
    ground.data.materials.append(diffuse("ground", (0.4, 0.4, 0.4)))
    scene.collection.objects.link(ground)
    paint = diffuse("paint", (0.7, 0.2, 0.1))
    for name, positions in spec["balls"].items():
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, segments=96, ring_count=48)
        ball = bpy.context.active_object
        ball.name = name
        bpy.ops.object.shade_smooth()
        ball.data.materials.append(paint)
        for t, p in zip(spec["times"], positions):
            ball.location = blender(p)
            ball.keyframe_insert("location", frame=float(t * fps))
        ball.cycles.motion_steps = 3
    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "HORIZONTAL"
    cam.angle = math.radians(50)
    cam_obj = bpy.data.objects.new("camera", cam)
    cam_obj.location = blender([0.0, 4.0, 14.0])
    cam_obj.rotation_mode = "QUATERNION"
    cam_obj.rotation_quaternion = (mathutils.Vector(blender([0.0, 0.5, 0.0])) - cam_obj.location).to_track_quat("-Z", "Y")
    scene.collection.objects.link(cam_obj)
    scene.camera = cam_obj
    scene.frame_set(spec["frame"])

    def render(name: str, spp: int, practical: bool, denoise: bool | None = None) -> float:
        scene.cycles.samples = spp
        scene.cycles.use_adaptive_sampling = practical
        scene.cycles.use_denoising = practical if denoise is None else denoise
        scene.cycles.use_light_tree = practical
        scene.render.filepath = str(out_dir / f"{name}.exr")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        return time.perf_counter() - t0

    if spec.get("one"):  # bench_startup.py: one frame in a fresh process, as a CI job renders it
        render("one", int(spec["one"]), False)
        return
    timings: dict[str, float] = {}
    render("warmup", 4, False)
    timings["reference"] = render("reference", spec["ref_spp"], False)
    for practical in (False, True) if spec["practical"] else (False,):
        render("warmup", 4, practical)
        for spp in spec["spps"]:
            key = f"{'practical' if practical else 'equal'}-{spp}"
            timings[key] = min(render(key, spp, practical) for _ in range(2))
    if spec["practical"]:  # OIDN alone (no adaptive sampling, no light tree): the denoiser against raw samples, as ours is measured
        render("warmup", 4, False, denoise=True)
        for spp in spec["spps"]:
            timings[f"denoised-{spp}"] = min(render(f"denoised-{spp}", spp, False, denoise=True) for _ in range(2))
    (out_dir / "timings.json").write_text(json.dumps(timings))


def cycles(path: Path, spps: list[int], ref_spp: int, practical: bool, python: str) -> dict[str, Any]:
    """Cycles at each count against its own reference, in a subprocess of `python` (a
    Python with `bpy`: it pins numpy < 2, so it lives in its own environment)."""
    import subprocess

    from motion.pipeline.frame_output import read_frame

    work = Path(tempfile.mkdtemp())
    spec = {**cycles_spec(path), "spps": spps, "ref_spp": ref_spp, "practical": practical}
    (work / "spec.json").write_text(json.dumps(spec))
    subprocess.run([python, str(Path(__file__).resolve()), "--cycles-worker", str(work / "spec.json")], check=True)
    timings = json.loads((work / "timings.json").read_text())

    def image(name: str) -> np.ndarray:
        return np.asarray(read_frame(work / f"{name}.exr").rgba, dtype=np.float32)

    reference = image("reference")
    out: dict[str, Any] = {"ref_spp": ref_spp, "reference_mean": float(reference[..., :3].mean())}
    for mode in ("equal", "practical", "denoised") if practical else ("equal",):
        rows = []
        for spp in spps:
            key = f"{mode}-{spp}"
            rows.append({"spp": spp, "seconds": timings[key], "rel_mse": rel_mse(image(key), reference)})
            print(f"  cycles {mode:9s} {spp:4d} spp  {timings[key]:7.3f} s  relMSE {rows[-1]['rel_mse']:.3e}", flush=True)
        out[mode] = rows
    return out


def summary(label: str, mine: list[tuple[float, float]], theirs: list[tuple[float, float]] | None) -> dict[str, Any]:
    """Time to each level, and ours / Cycles where both reach it."""
    out: dict[str, Any] = {}
    for level in LEVELS:
        a = time_to_error(mine, level)
        b = time_to_error(theirs, level) if theirs else None
        out[f"{level:.0e}"] = {"ours_s": a, "cycles_s": b, "ratio": (a / b) if a and b else None}
        ratio = f"  ours/cycles {a / b:.2f}x" if a and b else ""
        print(f"  {label} time to relMSE {level:.0e}: ours {a if a is None else round(a, 3)} s" + (f", cycles {round(b, 3)} s" if b else "") + ratio)
    return out


def main() -> None:
    """Measure and print; --json writes every figure."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spp", default="1,2,4,8,16,32,64,128,256")
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--shots", default="bench,walk-cycle")
    ap.add_argument("--denoise", action="store_true", help="also OIDN-denoised (ours), and OIDN + adaptive + light tree and OIDN alone (Cycles)")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--cycles-python", default=os.environ.get("BENCH_CYCLES_PYTHON", sys.executable), help="a Python with bpy (default: this one, or $BENCH_CYCLES_PYTHON)")
    ap.add_argument("--cycles-worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cycles_worker:
        cycles_worker(args.cycles_worker)
        return
    spps = [int(s) for s in args.spp.split(",")]
    import subprocess

    probe = subprocess.run([args.cycles_python, "-c", "import bpy"], capture_output=True, check=False) if not args.no_cycles else None
    have_cycles = probe is not None and probe.returncode == 0
    if not have_cycles and not args.no_cycles:
        print(f"bpy not importable by {args.cycles_python}: Cycles skipped (pip install bpy, Python 3.11; --cycles-python)")
    print(f"CPU: {cpu_model()}; {THREADS} threads; reference {args.ref_spp} spp; relMSE = mean((x-ref)^2/(ref^2+0.01))")
    results: dict[str, Any] = {"cpu": cpu_model(), "threads": THREADS}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.shots.split(","):
            path = {"bench": bench_shot, "lamps": lamps_shot, "walk-cycle": walk_shot}[name](Path(tmp), args.denoise)
            try:
                print(f"{name}:")
                res: dict[str, Any] = {"ours": ours(path, spps, args.ref_spp, args.denoise)}
                mine = [(r["seconds"], r["rel_mse"]) for r in res["ours"]["rows"]]
                theirs = None
                if have_cycles and name == "bench":
                    res["cycles"] = cycles(path, spps, args.ref_spp, args.denoise, args.cycles_python)
                    theirs = [(r["seconds"], r["rel_mse"]) for r in res["cycles"]["equal"]]
                if theirs:
                    print(f"  converged means: ours {res['ours']['reference_mean']:.4f}, cycles {res['cycles']['reference_mean']:.4f}")
                res["equal_settings"] = summary("equal settings", mine, theirs)
                if args.denoise:
                    rows = res["ours"]["rows"]
                    denoised = [(r["seconds"] + r["denoise_s"], r["denoised_rel_mse"]) for r in rows]
                    best = None
                    if have_cycles and name == "bench":
                        best = [(r["seconds"], r["rel_mse"]) for r in res["cycles"]["practical"]]
                    res["best_practical"] = summary("best practical", denoised, best)
                    by = {r["spp"]: r for r in rows}
                    if 16 in by and 256 in by:
                        print(f"  denoised 16 spp relMSE {by[16]['denoised_rel_mse']:.3e} vs raw 256 spp {by[256]['rel_mse']:.3e}")
                        if have_cycles and name == "bench":
                            cy = {m: {r["spp"]: r for r in res["cycles"][m]} for m in ("equal", "denoised")}
                            print(f"  cycles: OIDN-denoised 16 spp relMSE {cy['denoised'][16]['rel_mse']:.3e} vs raw 256 spp {cy['equal'][256]['rel_mse']:.3e}"
                                  f" (OIDN on 256 spp: {cy['denoised'][256]['rel_mse']:.3e})")
                results[name] = res
            finally:
                pass
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
