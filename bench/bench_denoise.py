"""Denoiser benchmark (issue 13): quality per second, cost, and temporal stability.

    python bench/bench_denoise.py [--quick]

Everything is measured side by side in one run on this machine, in one process, warm
(kernels compiled, the denoiser's filter made) unless said otherwise:
 1. quality: on the preview shot of bench_render.py (100k-triangle terrain, 4 orbiting
    plastic balls, 320x180, depth 4) and on the walk-cycle at 320x180, the relative MSE
    against a 4096-spp reference (1024 with --quick) of raw 16, 64, 256 spp and of 16 spp
    denoised (Intel Open Image Denoise, albedo + normal guides), with their times.
    Target: denoised 16 spp below raw 256 spp, in under 1/8 of its time (denoise included);
 2. cost: the denoiser's share of a warm 320x180 x 16 spp frame (target <= 10%), and its
    time on a 1920x1080 frame (target <= 0.5 s on 2 cores); its bits at 1 and 2 threads;
 3. flicker (the mean frame-to-frame change of pixels whose true value does not change):
    a static camera over a moving object (walk-cycle) and a trucking camera over the static
    set (the preview shot's camera moving 1.5 m/s), for per-frame seeds, fixed seeds and the
    temporal mode (`render.temporal: reproject`), against raw 256 spp. Target: temporal at
    most half of per-frame denoising, and no worse than raw 256 spp;
 4. ghosting: the sliding-bar test (an emissive bar moving 40 px within the shutter):
    error of the temporal mode's frame against the closed-form trapezoid, against raw 256 spp
    (target: within 2x).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))

from bench_render import shot, terrain_ply  # noqa: E402


class Shot:
    """A scene rendered in this process through the real pipeline (bake -> FrameRenderer)."""

    def __init__(self, path: Path, **render: Any) -> None:
        from motion.pipeline.render.worker.frame_renderer import FrameRenderer
        from motion.pipeline.bake import evaluate_frames
        from motion.pipeline.scene import load_scene

        import gc

        gc.collect()
        self.loaded = load_scene(path, {"render": render, "output": {"aovs": ["albedo", "normal", "motion"]}})
        self.renderer = FrameRenderer(self.loaded)
        self._inputs = {fi.frame: fi for fi in evaluate_frames(self.loaded, list(self.loaded.scene.timeline.timeline().frames)[:12])}

    def render(self, frame: int) -> tuple[np.ndarray, dict[str, np.ndarray], float]:
        t0 = time.perf_counter()
        rgba, aovs, _ = self.renderer.render_layers(self._inputs[frame])
        return rgba, aovs, time.perf_counter() - t0

    def shutter_fraction(self) -> float:
        fi = self._inputs[0]
        return float((fi.shutter[1] - fi.shutter[0]) * float(self.loaded.scene.timeline.rate))


def rel_mse(img: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((img[..., :3] - ref[..., :3]) ** 2 / (ref[..., :3] ** 2 + 1e-2)))


def denoise(rgba: np.ndarray, aovs: dict[str, np.ndarray], color: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    from motion.pipeline.render.output.denoise import denoise_frame

    t0 = time.perf_counter()
    out, _, _ = denoise_frame(rgba, aovs, color=color)
    return out, time.perf_counter() - t0


PREVIEW = {"resolution": (320, 180), "max_depth": 4, "filter": "box"}  # the preview preset


def quality(path: Path, label: str, ref_spp: int, frame: int) -> dict[str, Any]:
    ref, _, t_ref = Shot(path, spp=ref_spp, **PREVIEW).render(frame)
    out: dict[str, Any] = {"reference_spp": ref_spp, "reference_s": round(t_ref, 2)}
    for spp in (16, 64, 256):
        s = Shot(path, spp=spp, **PREVIEW)
        s.render(frame)  # warm
        img, aovs, t = s.render(frame)
        out[f"raw_{spp}"] = {"rel_mse": rel_mse(img, ref), "s": round(t, 3)}
        if spp == 16:
            denoise(img, aovs)  # the filter made once, as in a worker
            den, t_d = denoise(img, aovs)
            out["denoised_16"] = {"rel_mse": rel_mse(den, ref), "s": round(t + t_d, 3), "render_s": round(t, 3), "denoise_s": round(t_d, 3)}
    d, r = out["denoised_16"], out["raw_256"]
    out["target_lower_mse_than_raw_256"] = d["rel_mse"] < r["rel_mse"]
    out["time_ratio_vs_raw_256"] = round(d["s"] / r["s"], 3)
    out["target_under_1_8_of_the_time"] = d["s"] < r["s"] / 8
    print(label, json.dumps(out), flush=True)
    return out


def cost(path: Path) -> dict[str, Any]:
    import drjit as dr

    s = Shot(path, spp=16, **PREVIEW)
    s.render(0)
    img, aovs, _ = s.render(0)
    denoise(img, aovs)
    renders, dens = [], []
    for f in range(1, 4):
        img, aovs, t = s.render(f)
        _, t_d = denoise(img, aovs)
        renders.append(t)
        dens.append(t_d)
    out: dict[str, Any] = {"warm_frame_s": round(float(np.median(renders)), 3), "denoise_s": round(float(np.median(dens)), 3)}
    out["denoise_share"] = round(out["denoise_s"] / (out["warm_frame_s"] + out["denoise_s"]), 3)
    out["target_share_le_10pct"] = out["denoise_s"] <= 0.1 * out["warm_frame_s"]
    # 1080p: the same frame's layers upsampled (the denoiser's cost depends on the size only)
    big = {k: np.repeat(np.repeat(v, 6, axis=0), 6, axis=1)[:1080, :1920] for k, v in {"rgba": img, **aovs}.items()}
    rgba = big.pop("rgba")
    denoise(rgba, big)
    times = []
    for _ in range(2):
        times.append(denoise(rgba, big)[1])
    out["denoise_1080p_s"] = round(min(times), 3)
    out["target_1080p_le_0_5s"] = out["denoise_1080p_s"] <= 0.5
    # the floor under any pipeline: OIDN's RT filter alone (colour + albedo + normal, set up
    # once, best of 2), at each of its quality levels
    out["oidn_alone_s"] = oidn_alone({"320x180": (img, aovs), "1920x1080": (rgba, big)})
    # the same bits whatever the number of threads
    results = []
    for threads in (1, 2):
        dr.set_thread_count(threads)
        results.append(denoise(img, aovs)[0])
    out["same_bits_1_and_2_threads"] = bool(np.array_equal(results[0], results[1]))
    print("cost", json.dumps(out), flush=True)
    return out


def oidn_alone(images: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]) -> dict[str, float]:
    """Seconds of OIDN's own filter execution per image and quality (High is what the
    worker uses; Balanced and Fast trade quality for speed), the filter made beforehand."""
    import drjit as dr
    import mitsuba_oidn as oidn

    from motion.pipeline.render.kernel.aovs import layer

    device = oidn.Device(oidn.DeviceType.CPU)
    out: dict[str, float] = {}
    for size, (rgba, aovs) in images.items():
        color = np.ascontiguousarray(rgba[..., :3], dtype=np.float32)
        albedo = np.ascontiguousarray(np.clip(aovs[layer("albedo")][..., :3], 0, 1), dtype=np.float32)
        normal = np.ascontiguousarray(np.clip(aovs[layer("normal")][..., :3], -1, 1), dtype=np.float32)
        for quality in ("High", "Balanced", "Fast"):
            flt = device.new_filter("RT")
            flt.hdr, flt.quality, flt.input_scale = True, getattr(oidn.Quality, quality), 1.0
            result = np.zeros_like(color)
            for name, image in (("color", color), ("albedo", albedo), ("normal", normal), ("output", result)):
                flt.set_image(name, image)
            flt.execute()
            times = []
            for _ in range(2):
                start = time.perf_counter()
                flt.execute()
                times.append(time.perf_counter() - start)
            out[f"{size} {quality} ({dr.thread_count()} threads)"] = round(min(times), 3)
    return out


def _luma(img: np.ndarray) -> np.ndarray:
    return img[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def flicker(path: Path, label: str, n: int, ref_spp: int, res: tuple[int, int]) -> dict[str, Any]:
    """Mean |change| of luminance from frame k to k+1 over pixels whose true value does not
    change: reprojected by the reference's motion vectors (zero for a static camera's static
    set, the camera's motion for a trucking camera), the same albedo and normal there, and
    the reference's colour within 5%."""
    from motion.pipeline.render.output.temporal import RADIUS, blend, warp

    look = {**PREVIEW, "resolution": res}
    frames = list(range(n + 4))  # the temporal mode's neighbours on each side (radius 1 or 2)
    ref_shot = Shot(path, spp=ref_spp, **look)
    refs = [ref_shot.render(f)[:2] for f in frames]
    s_frac = ref_shot.shutter_fraction()
    del ref_shot

    def stable(k: int) -> tuple[np.ndarray, np.ndarray]:
        """Flow from frame k to k+1 and the pixels whose true value it carries unchanged."""
        ref_k, aov_k = refs[k]
        flow = aov_k["motion"] / s_frac if s_frac > 0 else np.zeros_like(aov_k["motion"])
        warped, inside = warp(refs[k + 1][0][..., :3], flow)
        same = np.abs(_luma(warped) - _luma(ref_k)) < 0.05 * (_luma(ref_k) + 0.02)
        for key, tol in (("albedo", 0.01), ("N", 0.02)):
            other, _ = warp(refs[k + 1][1][key], flow)
            same &= np.abs(other - aov_k[key]).max(axis=2) < tol
        return flow, inside & same

    pairs = range(2, n + 2)  # frame k to k + 1, each with two neighbours on either side
    masks = [stable(k) for k in pairs]

    def measure(images: list[np.ndarray]) -> float:
        diffs = []
        for (flow, mask), k in zip(masks, pairs):
            nxt, _ = warp(images[k + 1][..., :3], flow)
            diffs.append(np.abs(_luma(nxt) - _luma(images[k][..., :3]))[mask].mean())
        return float(np.mean(diffs))

    out: dict[str, Any] = {"frames": n, "stable_pixels": round(float(np.mean([m.mean() for _, m in masks])), 3)}
    per_frame = Shot(path, spp=16, **look)
    raw = [per_frame.render(f)[:2] for f in frames]
    out["raw_16"] = measure([r for r, _ in raw])
    out["per_frame_denoised"] = measure([denoise(r, a)[0] for r, a in raw])
    for radius in (1, 2):
        temporal = []
        for k in frames:
            cur = {"color": raw[k][0][..., :3], "albedo": raw[k][1]["albedo"], "N": raw[k][1]["N"], "motion": raw[k][1]["motion"]}
            near = [(d, {"color": raw[k + d][0][..., :3], "albedo": raw[k + d][1]["albedo"], "N": raw[k + d][1]["N"], "motion": raw[k + d][1]["motion"]}) for d in range(-radius, radius + 1) if d and 0 <= k + d < len(frames)]
            color, _ = blend(cur, near, s_frac)
            temporal.append(denoise(raw[k][0], raw[k][1], color=color)[0])
        out[f"temporal_reproject_radius_{radius}"] = measure(temporal)
    out["temporal_reproject"] = out[f"temporal_reproject_radius_{RADIUS}"]
    del per_frame
    fixed_shot = Shot(path, spp=16, **look, seed_policy="fixed")
    fixed = [fixed_shot.render(f)[:2] for f in frames]
    out["fixed_seed_denoised"] = measure([denoise(r, a)[0] for r, a in fixed])
    del fixed_shot
    hi = Shot(path, spp=256, **look)
    out["raw_256"] = measure([hi.render(f)[0] for f in frames])
    out["target_temporal_le_half_per_frame"] = out["temporal_reproject"] <= 0.5 * out["per_frame_denoised"]
    out["target_temporal_le_raw_256"] = out["temporal_reproject"] <= out["raw_256"]
    print(label, json.dumps(out), flush=True)
    return out


def ghosting(folder: Path) -> dict[str, Any]:
    """The sliding bar of tests/render/test_blur.py: frame 1 (blended with frames 0 and 2,
    all the shot has) against the closed-form trapezoid: raw, per-frame denoised and
    temporal, from 16 and from 256 spp."""
    from test_render_blur import _profile, _slide_scene, _trapezoid

    from motion.pipeline.render.output.temporal import blend

    path = folder / "slide.yaml"
    # 64 rows instead of the test's 4: OIDN needs an image, not a strip, to work on
    path.write_text(_slide_scene(spp=16).replace("resolution: [200, 4]", "resolution: [200, 64]"))
    expected = _trapezoid(1.0, 2.0)  # frame 1 (t = 1/24 s): the centre moves 1 -> 2 m in its shutter
    out: dict[str, Any] = {}
    for spp in (16, 256):
        s = Shot(path, spp=spp)
        raw = [s.render(f)[:2] for f in range(3)]
        cur = {"color": raw[1][0][..., :3], "albedo": raw[1][1]["albedo"], "N": raw[1][1]["N"], "motion": raw[1][1]["motion"]}
        near = [(d, {"color": raw[1 + d][0][..., :3], "albedo": raw[1 + d][1]["albedo"], "N": raw[1 + d][1]["N"], "motion": raw[1 + d][1]["motion"]}) for d in (-1, 1)]
        color, count = blend(cur, near, s.shutter_fraction())
        temporal = denoise(raw[1][0], raw[1][1], color=color)[0]
        per_frame = denoise(raw[1][0], raw[1][1])[0]
        bar = expected > 0
        out[f"spp_{spp}"] = {
            "raw_error": float(np.abs(_profile(raw[1][0]) - expected).mean()),
            "per_frame_denoised_error": float(np.abs(_profile(per_frame) - expected).mean()),
            "temporal_error": float(np.abs(_profile(temporal) - expected).mean()),
            "blended_share_on_the_bar": float((count > 1)[:, bar].mean()),
        }
        del s
    raw256 = out["spp_256"]["raw_error"]
    out["target_temporal_16_within_2x_raw_256"] = out["spp_16"]["temporal_error"] <= 2 * raw256
    out["target_temporal_256_within_2x_raw_256"] = out["spp_256"]["temporal_error"] <= 2 * raw256
    print("ghosting", json.dumps(out), flush=True)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="1024-spp references, fewer flicker frames at 160x90")
    parser.add_argument("--only", choices=["quality", "cost", "flicker", "ghosting"], help="run one part")
    args = parser.parse_args()
    from motion.pipeline import variant

    variant.activate("auto", quiet=True)
    import mitsuba as mi

    mi.set_log_level(mi.LogLevel.Error)  # the multijitter sampler's rounding notes
    results: dict[str, Any] = {"cpu": cpu_model(), "note": "a shared machine (other sessions running): figures are noisy; only ratios within this run compare"}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        terrain_ply(folder / "terrain.ply")
        preview = shot(folder, movers=4)
        walk = REPO / "scenes" / "walk-cycle.yaml"
        # the preview shot with its camera trucking sideways at 1.5 m/s over the static set
        truck = folder / "truck.yaml"
        text = preview.read_text().replace("fov: 50}", "fov: 50, shutter: {angle: 180}, motion: {type: procedural, generators: [{type: ballistic, v0: [1.5, 0, 0], a: [0, 0, 0]}]}}")
        truck.write_text(text)
        ref_spp = 1024 if args.quick else 4096
        if args.only in (None, "quality"):
            results["1_quality_preview"] = quality(preview, "quality preview", ref_spp, 3)
            results["1_quality_walk_cycle"] = quality(walk, "quality walk-cycle", ref_spp, 3)
        if args.only in (None, "cost"):
            results["2_cost"] = cost(preview)
        n = 4 if args.quick else 8
        flicker_ref = 1024 if args.quick else 4096
        flicker_res = (160, 90) if args.quick else (320, 180)
        if args.only in (None, "flicker"):
            results["3_flicker_static_camera_walk_cycle"] = flicker(walk, "flicker static camera (walk-cycle)", n, flicker_ref, flicker_res)
            results["3_flicker_moving_camera_preview"] = flicker(truck, "flicker trucking camera (preview shot)", n, flicker_ref, flicker_res)
        if args.only in (None, "ghosting"):
            results["4_ghosting_sliding_bar"] = ghosting(folder)
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
