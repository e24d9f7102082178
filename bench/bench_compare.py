"""How often `motion compare` cries wolf, how small a change it catches, how fast it is.

    python bench/bench_compare.py                 # all three parts, short
    python bench/bench_compare.py --seeds 1000    # false alarms over 1000 seed pairs per scene
    python bench/bench_compare.py --part speed    # 72 frames at 480x270
    python bench/bench_compare.py --part kappa    # the noise correlation factor per filter

1. False alarms: unchanged scenes (the examples at their ci-smoke settings, 64x36, 4 spp,
   plus a still test set) rendered with many seeds in this process (the real renderer, one
   FrameRenderer per scene, `render.seed` changed between renders); disjoint pairs of seeds
   are tested (stats.compare_frame) and every pair that is called different is a false alarm.
2. Smallest change caught: a still set at 64x36 (a 5% patch of its own material, a ball, a
   sun), changed by a 2% albedo change on the patch, the ball moved by one pixel, the sun
   5% dimmer; the fraction of seed pairs in which each is caught, at several spp.
3. Speed: 72 frames at 480x270 (RGBA + a noisy layer, half floats, as the showcase writes
   them) compared by `compare_sequences` with 2 processes.

The CPU model is printed beside the figures.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

# A still set: a grey floor, a patch of its own material covering 5.0% of the frame (0.78 x 0.5
# turned 15 degrees, 5 units away: 0.377 of the 7.5 square units the frame spans there), a
# ball, a sun and a sky.
STILL = """
name: still
timeline: {{fps: 24, first: 0, last: 0}}
camera: {{position: [0, 1.0, 5], look_at: [0, 0.5, 0], fov: 40, shutter: {{angle: 180}}}}
lights:
  - {{type: constant, radiance: 0.4}}
  - {{type: directional, direction: [-0.5, -1, -0.4], irradiance: {sun}}}
materials:
  - {{name: floor, type: diffuse, color: 0.5}}
  - {{name: patch, type: diffuse, color: [{patch}, {patch}, {patch}]}}
  - {{name: ball, type: plastic, color: [0.7, 0.2, 0.1], roughness: 0.3}}
objects:
  - {{name: floor, shape: rectangle, width: 20, height: 20, material: floor, transform: {{rotate: {{euler: [-90, 0, 0]}}}}}}
  - {{name: patch, shape: rectangle, width: 0.78, height: 0.5, material: patch, transform: {{translate: [-1.0, 0.9, 0], rotate: {{euler: [0, 15, 0]}}}}}}
  - {{name: ball, shape: sphere, radius: 0.35, material: ball, transform: {{translate: [{ball_x}, 0.35, 0.5]}}}}
render: {{resolution: [{w}, {h}], spp: {spp}, max_depth: 3}}
"""
STILL_BASE = {"sun": 3.0, "patch": 0.5, "ball_x": 0.8, "w": 64, "h": 36, "spp": 4}


def _pixel_world(fov_deg: float, distance: float, width: int) -> float:
    """World size of one pixel at `distance` for a horizontal fov over `width` pixels."""
    return 2.0 * distance * np.tan(np.radians(fov_deg) / 2.0) / width


def _renderer(scene_path: Path, overrides: dict[str, Any] | None = None) -> tuple[Any, list[Any]]:
    from motion.pipeline import variant
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.scene import load_scene

    variant.activate("auto", quiet=True)
    import gc

    gc.collect()
    loaded = load_scene(scene_path, overrides=overrides)
    frames = list(range(loaded.scene.timeline.first, loaded.scene.timeline.last + 1))
    from motion.pipeline.presets import spread

    count = (overrides or {}).get("frame_count")
    picked = spread(frames, count) if count else frames
    return FrameRenderer(loaded), list(evaluate_frames(loaded, picked))


def seeded(renderer: Any, baked: list[Any], seeds: Iterator[int] | list[int]) -> Iterator[tuple[int, int, np.ndarray]]:
    """(seed, frame index, RGBA) for every seed and frame: the same picture, its noise drawn anew."""
    base = renderer.settings
    for seed in seeds:
        renderer.settings = base.model_copy(update={"seed": int(seed)})
        for i, fi in enumerate(baked):
            rgba, _ = renderer.render(fi)
            yield seed, i, rgba.astype(np.float16).astype(np.float32)  # as the frames are stored
    renderer.settings = base


def _ci_smoke() -> dict[str, Any]:
    from motion.pipeline.presets import load_preset, overrides_from

    preset, _ = load_preset("ci-smoke")
    out = overrides_from(preset, {})
    out["frame_count"] = preset.frame_count
    return out


def _kappa_of(renderer: Any) -> float:
    from motion.pipeline.compare.stats import FILTER_KAPPA

    return FILTER_KAPPA[renderer.settings.filter]


def false_alarms(scenes: list[Path], pairs: int) -> list[dict[str, Any]]:
    """Per scene: frames tested, false alarms, the largest |z| seen and the threshold."""
    from motion.pipeline.compare.stats import compare_frame

    rows = []
    smoke = _ci_smoke()
    for path in scenes:
        over = {k: v for k, v in smoke.items() if k != "frame_count"}
        renderer, baked = _renderer(path, over)
        baked = baked[:: max(1, len(baked) // 3)][:3] if len(baked) > 3 else baked
        n_seeds = 2 * -(-pairs // len(baked))
        t0 = time.perf_counter()
        images: dict[int, list[np.ndarray]] = {}
        for seed, i, rgba in seeded(renderer, baked, range(1000, 1000 + n_seeds)):
            images.setdefault(i, []).append(rgba)
        render_s = time.perf_counter() - t0
        alarms, tested, zs, thr = 0, 0, [], 0.0
        for i, imgs in images.items():
            for k, (a, b) in enumerate(zip(imgs[0::2], imgs[1::2])):
                t = compare_frame(a, b, kappa=_kappa_of(renderer))
                tested += 1
                zs.append(t.max_z)
                thr = t.threshold
                if t.verdict == "different":
                    alarms += 1
                    print(f"    false alarm: frame {i}, seeds {1000 + 2 * k} and {1001 + 2 * k}: {t.regions[0].describe()}", flush=True)
        rows.append({"scene": path.stem, "tested": tested, "false_alarms": alarms, "max_z": float(max(zs)), "median_max_z": float(np.median(zs)),
                     "threshold": thr, "render_s": render_s})
        print(f"  {path.stem:18s} {tested:5d} pairs  {alarms:3d} false alarms  largest |z| {max(zs):5.2f} (median {np.median(zs):4.2f}) threshold {thr:4.2f}  ({render_s:.0f} s rendering)", flush=True)
    return rows


def _still(tmp: Path, name: str, **changes: Any) -> Path:
    path = tmp / f"{name}.yaml"
    path.write_text(STILL.format(**{**STILL_BASE, **changes}))
    return path


def sensitivity(spps: list[int], pairs: int) -> list[dict[str, Any]]:
    """Per change and spp: the fraction of seed pairs in which the change is caught, and
    whether the region that differs most overlaps the changed object's box."""
    from motion.pipeline.compare.stats import compare_frame

    px = _pixel_world(40.0, 4.6, STILL_BASE["w"])
    changes = {"none": {}, "albedo 2% on 5% region": {"patch": 0.5 * 1.02}, "ball moved 1 px": {"ball_x": STILL_BASE["ball_x"] + px}, "sun 5% dimmer": {"sun": 3.0 * 0.95}}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for spp in spps:
            refs: list[np.ndarray] = []
            renderer, baked = _renderer(_still(Path(tmp), "base", spp=spp))
            refs = [img for _, _, img in seeded(renderer, baked, range(pairs))]
            for label, change in changes.items():
                renderer, baked = _renderer(_still(Path(tmp), "changed", spp=spp, **change))
                news = [img for _, _, img in seeded(renderer, baked, range(5000, 5000 + pairs))]
                caught = sum(compare_frame(n, r, kappa=_kappa_of(renderer)).verdict == "different" for n, r in zip(news, refs))
                rows.append({"change": label, "spp": spp, "caught": caught, "pairs": pairs})
                print(f"  {spp:5d} spp  {label:26s} caught in {caught:4d} of {pairs} seed pairs", flush=True)
    return rows


def kappa(pairs: int, spps: tuple[int, ...] = (4, 64)) -> None:
    """The noise correlation factor per reconstruction filter (stats.FILTER_KAPPA): over
    `pairs` seed pairs of the still set, the variance of a window's sum of D over the mean
    sum of its Immerkaer v, for 4-, 8- and 16-pixel windows (median over windows, and
    the ratio of the sums)."""
    from motion.pipeline.compare import stats as S

    with tempfile.TemporaryDirectory() as tmp:
        for filt in ("gaussian", "box", "tent"):
            for spp in spps:
                path = Path(tmp) / f"{filt}{spp}.yaml"
                path.write_text(STILL.format(**{**STILL_BASE, "spp": spp}).replace("max_depth: 3}", f"max_depth: 3, filter: {filt}}}"))
                renderer, baked = _renderer(path)
                imgs = np.array([img for _, _, img in seeded(renderer, baked, range(2 * pairs))], dtype=np.float64)
                d = imgs[0::2] - imgs[1::2]
                cells = []
                for b in (4, 8, 16):
                    sd = np.array([S._block_sums(x, b) for x in d])[..., :3]
                    sv = np.array([S._block_sums(S._immerkaer(x), b) for x in d]).mean(0)[..., :3]
                    ok = sv > 1e-6
                    var = sd.var(0)[ok]
                    cells.append(f"{b:2d} px: {np.median(var / sv[ok]):5.2f} / {var.sum() / sv[ok].sum():5.2f}")
                print(f"  {filt:8s} {spp:4d} spp  kappa (median / ratio of sums)  " + "   ".join(cells), flush=True)


def speed(frames: int = 72, size: tuple[int, int] = (480, 270)) -> dict[str, Any]:
    """Seconds to compare `frames` frames of `size` (two sequences of synthetic renders:
    one picture, independent noise, RGBA + noisy layer, half floats) with 2 processes."""
    from motion.pipeline.compare import compare_sequences
    from motion.pipeline.frame_output import write_frame

    w, h = size
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:h, 0:w] / float(h)
    picture = np.stack([0.2 + 0.6 * xx / 2, 0.3 + 0.4 * yy, 0.5 + 0.2 * np.sin(6 * xx), np.ones_like(xx)], axis=2)
    with tempfile.TemporaryDirectory() as tmp:
        for side in ("new", "ref"):
            for n in range(frames):
                noisy = picture * (1 + 0.2 * rng.standard_normal(picture.shape))
                noisy[..., 3] = 1
                meta = {"frame": n, "variant": "llvm_ad_rgb", "seed": n, "spp": 8, "scene_hash": "s", "renderer": "motion-render-1", "render_settings": '{"spp": 8}'}
                write_frame(Path(tmp) / side / f"shot.{n:04d}.exr", picture, meta, aovs={"noisy": noisy}, pixel_type="half")
        best = float("inf")
        for _ in range(2):
            t0 = time.perf_counter()
            result = compare_sequences(Path(tmp) / "new", Path(tmp) / "ref", workers=2)
            best = min(best, time.perf_counter() - t0)
        counts = result.counts()
    print(f"  {frames} frames at {w}x{h}: {best:.2f} s with 2 processes ({counts})", flush=True)
    return {"frames": frames, "size": size, "seconds": best, "counts": counts}


def main() -> None:
    """Run the parts asked for and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["all", "false-alarms", "sensitivity", "speed", "kappa"], default="all")
    parser.add_argument("--seeds", type=int, default=200, help="seed pairs per scene for the false-alarm rate")
    parser.add_argument("--pairs", type=int, default=20, help="seed pairs per change and spp for the sensitivity")
    parser.add_argument("--spp", default="4,16,64,256,1024", help="spp for the sensitivity")
    parser.add_argument("--scenes", default="bouncing-balls,spinning-top,walker,walk-cycle,cannonball-splash")
    args = parser.parse_args()
    print(f"motion compare bench on {cpu_model()}")
    if args.part in ("all", "false-alarms"):
        print(f"false alarms: unchanged scenes, ci-smoke settings, {args.seeds} seed pairs each")
        rows = false_alarms([ROOT / "scenes" / f"{s}.yaml" for s in args.scenes.split(",")], args.seeds)
        tested, alarms = sum(r["tested"] for r in rows), sum(r["false_alarms"] for r in rows)
        print(f"  total: {alarms} false alarms in {tested} frame pairs ({alarms / max(tested, 1):.2e})")
    if args.part in ("all", "sensitivity"):
        print(f"smallest change caught: still set at {STILL_BASE['w']}x{STILL_BASE['h']}, {args.pairs} seed pairs per cell")
        sensitivity([int(s) for s in args.spp.split(",")], args.pairs)
    if args.part in ("all", "kappa"):
        print("kappa by filter: still set at 64x36")
        kappa(max(8, args.pairs))
    if args.part in ("all", "speed"):
        print("speed:")
        speed()


if __name__ == "__main__":
    main()
