"""Renderer benchmark: the first-frame cache and stochastic motion blur (issue 5).

    python bench/bench_render.py [--quick]

Everything is measured side by side in one run on this machine:
 1. cold vs warm frame time on a preview shot (320x180, 16 spp, depth 4) with a
    100k-triangle static set and moving bodies; warm frame vs the pure kernel time of the
    same render repeated with nothing changed (target <= 1.1x);
 2. frames per minute, cached worker vs a fresh process per frame (target >= 3x at
    preview), at ci-smoke, preview and final;
 3. motion-blur cost vs a static render at equal spp: 1, 4, 16 rigid movers and a
    10,000-particle system (target <= 1.5x for 4 movers);
 4. error against the analytic sliding-bar profile at equal render time, stochastic vs
    sub-frames (target: stochastic at most half);
 5. peak memory of a worker over 100 warm frames (flat).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MOTION = str(Path(sys.executable).with_name("motion"))


def terrain_ply(path: Path, n: int = 224) -> int:
    """A bumpy ground grid of 2 (n-1)^2 triangles (~100k for n = 224), written as PLY."""
    x, z = np.meshgrid(np.linspace(-20, 20, n), np.linspace(-20, 20, n))
    y = 0.3 * np.sin(x * 0.7) * np.cos(z * 0.5) + 0.1 * np.sin(3 * x + z)
    verts = np.column_stack([x.ravel(), y.ravel(), z.ravel()]).astype(np.float32)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n, i.ravel() + n + 1
    faces = np.concatenate([np.column_stack([a, c, b]), np.column_stack([b, c, d])]).astype(np.int32)
    with open(path, "wb") as f:
        f.write(
            f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n".encode()
        )
        rec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
        rec["n"], rec["i"] = 3, faces
        f.write(verts.tobytes())
        f.write(rec.tobytes())
    return len(faces)


def shot(folder: Path, movers: int, particles: int = 0, blur: str = "stochastic", res: tuple[int, int] = (320, 180), spp: int = 16, depth: int = 4, last: int = 200) -> Path:
    objects = [
        "  - {name: ground, shape: mesh, file: terrain.ply, material: ground}",
    ]
    for k in range(movers):
        x = -6 + 12 * (k + 0.5) / max(movers, 1)
        objects.append(
            f"  - {{name: ball{k}, shape: sphere, radius: 0.5, material: paint, transform: {{translate: [{x:.3f}, 1.2, 0]}},"
            f" motion: {{type: procedural, generators: [{{type: orbit, center: [{x:.3f}, 1.2, 0], radius: 0.8, period: 0.5}}]}}}}"
        )
    if particles:
        rate = particles / 2.0
        objects.append(
            f"  - {{name: spray, shape: particles, radius: 0.03, material: paint, emitter: {{rate: {rate}, lifetime: 2.0, position: [0, 0.5, 2],"
            f" direction: [0, 1, 0], speed: 4, spread: 30, seed: 1, max_count: {particles * 2}}}}}"
        )
    text = f"""
name: bench
timeline: {{fps: 24, first: 0, last: {last}}}
camera: {{position: [0, 4, 14], look_at: [0, 0.5, 0], fov: 50}}
lights: [{{type: constant, radiance: 0.4}}, {{type: directional, direction: [-0.4, -1, -0.3], irradiance: 2.5}}]
materials: [{{name: ground, type: diffuse, color: 0.4}}, {{name: paint, type: plastic, color: [0.7, 0.2, 0.1], roughness: 0.3}}]
objects:
{chr(10).join(objects)}
render: {{resolution: [{res[0]}, {res[1]}], spp: {spp}, max_depth: {depth}, motion_blur: {blur}, shutter_samples: 9}}
"""
    path = folder / f"bench-{movers}-{particles}-{blur}-{res[0]}-{spp}.yaml"
    path.write_text(text)
    return path


def _sync() -> None:
    import drjit as dr

    dr.sync_thread()


def cache_figures(folder: Path, frames: int) -> dict[str, float]:
    """1. cold vs warm vs pure kernel, in this process."""
    import mitsuba as mi

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    loaded = load_scene(shot(folder, movers=4))
    inputs = evaluate_frames(loaded, list(range(frames + 1)))
    renderer = FrameRenderer(loaded)
    t0 = time.perf_counter()
    _, cold = renderer.render(inputs[0])
    cold_total = time.perf_counter() - t0
    warm, kernel = [], []
    for fi in inputs[1:]:
        t0 = time.perf_counter()
        img, st = renderer.render(fi)
        warm.append(time.perf_counter() - t0)
        # the same frame again with nothing changed: the kernel alone (+ readback)
        t0 = time.perf_counter()
        again = mi.render(renderer._scene, seed=1, spp=renderer.spp)
        np.array(again)
        kernel.append(time.perf_counter() - t0)
    w, k = float(np.median(warm)), float(np.median(kernel))
    return {"cold_s": cold_total, "cold_setup_s": cold.setup_s, "warm_s": w, "pure_kernel_s": k, "warm_over_kernel": w / k, "cold_over_warm": cold_total / w}


_COLD_PROBE = """
import json, sys, time
t0 = time.perf_counter()
from motion.pipeline import variant
variant.activate("auto", quiet=True)
from motion.pipeline.render.worker.frame_renderer import FrameRenderer
from motion.pipeline.bake import evaluate_frames
from motion.pipeline.scene import load_scene
loaded = load_scene(sys.argv[1])
inputs = evaluate_frames(loaded, [0, 1, 2])
t_import = time.perf_counter() - t0
renderer = FrameRenderer(loaded)
out = {"startup_s": t_import}
for fi in inputs:
    t = time.perf_counter(); _, st = renderer.render(fi)
    out.setdefault("frames", []).append({"total_s": time.perf_counter() - t, "setup_s": st.setup_s, "compiled": st.kernels_compiled})
print(json.dumps(out))
"""


def cold_empty_caches(folder: Path) -> dict[str, object]:
    """1b. a new worker process with EMPTY kernel and asset caches: the real first frame."""
    scene = shot(folder, movers=4)
    env = dict(os.environ, MOTION_CACHE_DIR=str(folder / "empty-cache"))
    env.pop("DRJIT_CACHE_DIR", None)
    proc = subprocess.run([sys.executable, "-c", _COLD_PROBE, str(scene)], capture_output=True, text=True, check=True, env=env)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    f = out["frames"]
    out["cold_over_warm"] = f[0]["total_s"] / f[2]["total_s"]
    return out


def fpm_figures(folder: Path, preset_args: list[str], frames: int, label: str, scene: Path | None = None) -> dict[str, float]:
    """2. frames/min: one cached worker vs a fresh process per frame (the naive farm), on
    the bench shot or on `scene` (frames 0 .. frames-1)."""
    scene = scene or shot(folder, movers=4, last=frames)
    out = folder / f"fpm-{label}"
    t0 = time.perf_counter()
    subprocess.run([MOTION, "render", str(scene), *preset_args, "--frames", f"0-{frames - 1}", "--workers", "1", "--no-progress", "-o", str(out / "cached")], check=True, capture_output=True)
    cached = time.perf_counter() - t0
    t0 = time.perf_counter()
    for f in range(frames):
        subprocess.run([MOTION, "render", str(scene), *preset_args, "--frames", str(f), "--workers", "1", "--no-cache", "--no-progress", "-o", str(out / "naive")], check=True, capture_output=True)
    naive = time.perf_counter() - t0
    return {"frames": frames, "cached_fpm": 60 * frames / cached, "naive_fpm": 60 * frames / naive, "ratio": naive / cached}


def static_twin(moving: Path, fi: object) -> Path:
    """The same shot frozen at the frame's time: every rigid object in the one static BVH
    (movers at their frame pose) and motion blur off (particles drawn at the frame's
    time), i.e. a render with no motion."""
    import yaml

    doc = yaml.safe_load(moving.read_text())
    objects = []
    for obj in doc["objects"]:
        obj = dict(obj)
        name = obj["name"]
        if "motion" in obj:
            t = fi.at_frame.objects[name].translation[0]
            obj.pop("motion")
            obj["transform"] = {"translate": [float(x) for x in t]}
        objects.append(obj)
    doc["objects"] = objects
    doc["render"]["motion_blur"] = "off"
    path = moving.with_name(moving.stem + "-static.yaml")
    path.write_text(yaml.safe_dump(doc))
    return path


def _warm_time(path: Path, frames: list[int]) -> tuple[float, object]:
    import gc

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    gc.collect()
    loaded = load_scene(path)
    inputs = evaluate_frames(loaded, frames)
    renderer = FrameRenderer(loaded)
    renderer.render(inputs[0])
    ts = []
    for fi in inputs[1:]:
        t0 = time.perf_counter()
        renderer.render(fi)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), inputs[0]


def blur_cost(folder: Path, frames: int) -> dict[str, object]:
    """3. warm frame time with stochastic motion blur vs the static twin, equal spp."""
    out: dict[str, object] = {}
    for label, movers, particles in (("1 mover", 1, 0), ("4 movers", 4, 0), ("16 movers", 16, 0), ("10k particles", 0, 10000)):
        moving = shot(folder, movers=movers, particles=particles)
        t_blur, fi0 = _warm_time(moving, list(range(40, 41 + frames)))
        t_static, _ = _warm_time(static_twin(moving, fi0), list(range(40, 41 + frames)))
        out[label] = {"static_s": t_static, "stochastic_s": t_blur, "ratio": t_blur / t_static}
    return out


def blur_error(folder: Path) -> dict[str, float]:
    """4. RMS error against the analytic sliding-bar trapezoid at (about) equal time."""
    sys.path.insert(0, str(REPO / "tests"))
    import test_render_blur as T

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    expected = T._trapezoid(-1.0, 0.0)
    out = {}
    for label, text in (
        ("stochastic 64 spp", T._slide_scene(spp=64)),
        ("subframes 8 x 8 spp", T._slide_scene(mode="subframes", spp=64, subframes=8)),
        ("subframes 4 x 16 spp", T._slide_scene(mode="subframes", spp=64, subframes=4)),
    ):
        path = folder / f"slide-{label.replace(' ', '_')}.yaml"
        path.write_text(text)
        loaded = load_scene(path)
        (fi,) = evaluate_frames(loaded, [0])
        renderer = FrameRenderer(loaded)
        renderer.render(fi)  # warm up (kernels)
        ts, errs = [], []
        for _ in range(3):
            t0 = time.perf_counter()
            img, _ = renderer.render(fi)
            ts.append(time.perf_counter() - t0)
            errs.append(float(np.sqrt(np.mean((img[..., 0].mean(axis=0) - expected) ** 2))))
        out[label] = {"seconds": float(np.median(ts)), "rms_error": float(np.mean(errs))}
    out["stochastic_over_subframes8_error"] = out["stochastic 64 spp"]["rms_error"] / out["subframes 8 x 8 spp"]["rms_error"]
    return out


_MEMORY_PROBE = """
import json, sys, psutil
from motion.pipeline import variant
variant.activate("auto", quiet=True)
from motion.pipeline.render.worker.frame_renderer import FrameRenderer
from motion.pipeline.bake import evaluate_frames
from motion.pipeline.scene import load_scene
loaded = load_scene(sys.argv[1])
frames = int(sys.argv[2])
inputs = evaluate_frames(loaded, list(range(frames)))
renderer = FrameRenderer(loaded)
proc = psutil.Process()
rss = []
for fi in inputs:
    renderer.render(fi)
    rss.append(proc.memory_info().rss / 2**20)
print(json.dumps(rss))
"""


def memory(folder: Path, frames: int) -> dict[str, object]:
    """5. a worker's resident memory over `frames` warm frames, in a fresh process."""
    scene = shot(folder, movers=4, res=(64, 36), spp=4, last=frames)
    proc = subprocess.run([sys.executable, "-c", _MEMORY_PROBE, str(scene), str(frames)], capture_output=True, text=True, check=True)
    rss = json.loads(proc.stdout.strip().splitlines()[-1])
    marks = {k: round(rss[k - 1], 1) for k in (1, 10, frames // 2, frames)}
    return {"rss_mb_after_frame": marks, "growth_frame10_to_last_mb": round(rss[-1] - rss[9], 2)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer frames (a smoke run of the benchmark)")
    parser.add_argument("--fpm-shot", type=Path, help="only figure 2, on this scene at its own settings (e.g. scenes/cannonball-splash.yaml, the make render shot)")
    parser.add_argument("--fpm-frames", type=int, default=24, help="frames for --fpm-shot (default 24)")
    args = parser.parse_args()
    if args.fpm_shot is not None:
        from _common import cpu_model

        with tempfile.TemporaryDirectory() as tmp:
            figures = fpm_figures(Path(tmp), [], args.fpm_frames, "shot", args.fpm_shot.resolve())
        print(json.dumps({"cpu": cpu_model(), "shot": str(args.fpm_shot), "2_frames_per_minute": figures}, indent=1))
        return 0
    from motion.pipeline import variant

    choice = variant.activate("auto", quiet=True)
    import mitsuba as mi

    mi.set_log_level(mi.LogLevel.Error)
    n = 3 if args.quick else 10
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        tris = terrain_ply(folder / "terrain.ply")
        results: dict[str, object] = {"variant": choice.variant, "static_triangles": tris, "threads": os.cpu_count()}
        results["1_cache_preview"] = cache_figures(folder, n)
        print(json.dumps({"1_cache_preview": results["1_cache_preview"]}, indent=1), flush=True)
        results["1b_cold_empty_caches"] = cold_empty_caches(folder)
        print(json.dumps({"1b_cold_empty_caches": results["1b_cold_empty_caches"]}, indent=1), flush=True)
        results["3_blur_cost"] = blur_cost(folder, n)
        print(json.dumps({"3_blur_cost": results["3_blur_cost"]}, indent=1), flush=True)
        results["4_blur_error"] = blur_error(folder)
        print(json.dumps({"4_blur_error": results["4_blur_error"]}, indent=1), flush=True)
        results["5_memory"] = memory(folder, 30 if args.quick else 100)
        print(json.dumps({"5_memory": results["5_memory"]}, indent=1), flush=True)
        fpm = {}
        for label, preset, frames in (("ci-smoke", ["--preset", "ci-smoke"], 6 if args.quick else 12), ("preview", ["--preset", "preview"], 4 if args.quick else 10), ("final", ["--preset", "final"], 1)):
            if args.quick and label == "final":
                continue
            fpm[label] = fpm_figures(folder, preset, frames, label)
            print(json.dumps({label: fpm[label]}), flush=True)
        results["2_frames_per_minute"] = fpm
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
