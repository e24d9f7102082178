"""Lights benchmark: agreement with Mitsuba's `path` for the lights of the issue's table, and
what moving lights and emitters on movers cost (issue 17).

    python bench/bench_lights.py [--quick]

Everything is measured side by side in one run on this machine:
 1. A diffuse floor lit by one light, rendered by our worker (warm frame) and by Mitsuba's
    `path` integrator on a scene written here in Mitsuba's own terms (same camera, spp,
    filter, depth): mean of the frame, ours / path. Rows: directional straight down,
    directional along the examples' sun, point 3 m above the floor, spot from 3 m looking
    down, constant environment.
 2. Cost of a light that moves within the shutter (posed per path in the integrator) vs the
    same light still (a Mitsuba emitter in the static scene), warm frame, equal spp.
 3. A small area light on a mover (sampled in its rest frame with MIS) vs the same light in
    the static set: warm frame time and RMS error against a converged reference at equal spp.
 4. `--examples`: each example shot (scenes/*.yaml) at a third of its length, ours vs
    Mitsuba's `path` on the same records at the same instant (motion blur off): the mean of
    the ground (pixels whose normal points up) and its lit/shadow contrast (90th / 10th
    percentile of the ground's luminance).
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _light_scenes import light_scene_yaml, reference_scene  # noqa: E402

RES = (160, 120)


def scene_yaml(lights: str, objects: str = "", spp: int = 16, blur: str = "stochastic") -> str:
    return light_scene_yaml(lights, objects, resolution=RES, spp=spp, blur=blur, last=8)


def reference(mi: Any, emitters: dict[str, Any], spp: int, shapes: dict[str, Any] | None = None) -> Any:
    """The same floor and camera in Mitsuba's own terms, lit by `emitters`, with `path`."""
    return reference_scene(mi, emitters, shapes, resolution=RES, spp=spp)


def load(folder: Path, text: str, name: str) -> Any:
    from motion.pipeline.scene import load_scene

    path = folder / name
    path.write_text(text)
    return load_scene(path)


def warm_frames(loaded: Any, frames: list[int]) -> tuple[list[np.ndarray], list[float]]:
    """Frames rendered by one worker-style renderer: images and render seconds (the first
    frame, cold, is rendered and dropped)."""
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames

    gc.collect()
    renderer = FrameRenderer(loaded)
    inputs = evaluate_frames(loaded, frames)
    renderer.render(inputs[0])
    images, seconds = [], []
    for fi in inputs[1:]:
        t0 = time.perf_counter()
        img, _ = renderer.render(fi)
        seconds.append(time.perf_counter() - t0)
        images.append(img[..., :3])
    return images, seconds


def spot_to_world(mi: Any) -> Any:
    return mi.ScalarTransform4f().look_at(origin=[0, 3, 0], target=[0, 0, 0], up=[0, 0, 1])


def table_rows(mi: Any) -> list[tuple[str, str, Any]]:
    return [
        ("directional, straight down, irradiance 2.5", "  - {type: directional, direction: [0, -1, 0], irradiance: 2.5}", {"type": "directional", "direction": [0, -1, 0], "irradiance": 2.5}),
        (
            "directional [-0.4, -1, -0.3] (the examples' sun)",
            "  - {type: directional, direction: [-0.4, -1, -0.3], irradiance: 2.5}",
            {"type": "directional", "direction": [-0.4, -1, -0.3], "irradiance": 2.5},
        ),
        ("point at 3 m above the floor", "  - {type: point, position: [0, 3, 0], intensity: 10}", {"type": "point", "position": [0, 3, 0], "intensity": 10.0}),
        ("spot from 3 m, looking down", "  - {type: spot, position: [0, 3, 0], look_at: [0, 0, 0], intensity: 10}", {"type": "spot", "to_world": spot_to_world(mi), "intensity": 10.0}),
        ("constant environment", "  - {type: constant, radiance: 0.4}", {"type": "constant", "radiance": 0.4}),
    ]


def agreement(folder: Path, spp: int) -> list[dict[str, Any]]:
    import mitsuba as mi

    rows = []
    for k, (label, yaml_light, emitter) in enumerate(table_rows(mi)):
        (ours,), _ = warm_frames(load(folder, scene_yaml(yaml_light, spp=spp, blur="off"), f"row{k}.yaml"), [0, 1])
        ref = np.array(mi.render(reference(mi, {"light": emitter}, spp), seed=3))[..., :3]
        rows.append({"light": label, "ours": float(ours.mean()), "path": float(ref.mean()), "ratio": float(ours.mean() / ref.mean())})
    return rows


KEYED = "motion: {{type: keyframes, interpolation: linear, channels: {{{channel}: {{keys: [{{time: 0, value: {a}}}, {{time: 8, value: {b}}}]}}}}}}"
LAMP = (
    "  - {{name: lamp, shape: rectangle, width: 0.3, height: 0.3, emission: {{radiance: 80.0}}, material: black, "
    "transform: {{translate: [-0.5, 2.0, 0], rotate: {{euler: [90, 0, 0]}}}}{motion}}}"
)


def costs(folder: Path, spp: int, frames: int) -> dict[str, Any]:
    import mitsuba as mi

    out: dict[str, Any] = {}
    sky = "  - {type: constant, radiance: 0.02}"
    cases = {
        "point light, still": sky + "\n  - {type: point, position: [0, 3, 0], intensity: 10}",
        "point light, moving within the shutter": sky
        + "\n  - {type: point, position: [0, 3, 0], intensity: 10, "
        + KEYED.format(channel="translate", a="[-3, 3, 0]", b="[3, 3, 0]")
        + "}",
    }
    for label, lights in cases.items():
        _, seconds = warm_frames(load(folder, scene_yaml(lights, spp=spp), f"{len(out)}.yaml"), list(range(frames + 1)))
        out[label] = {"warm_s": statistics.median(seconds)}
    # a small area light, static vs on a mover that holds still: time and error at equal spp
    T = mi.ScalarTransform4f
    lamp = {
        "lamp": {
            "type": "rectangle",
            "emitter": {"type": "area", "radiance": 80.0},
            "bsdf": {"type": "diffuse", "reflectance": 0.0},
            "to_world": T().translate([-0.5, 2.0, 0]) @ T().rotate([1, 0, 0], 90) @ T().scale([0.15, 0.15, 1]),
        }
    }
    ref = np.array(mi.render(reference(mi, {"sky": {"type": "constant", "radiance": 0.02}}, 1024, lamp), seed=9))[..., :3]
    for label, motion in (("area light 0.3 m, static set", ""), ("area light 0.3 m, on a mover", ", " + KEYED.format(channel="translate", a="[-0.5, 2.0, 0]", b="[-0.5, 2.0, 0]"))):
        images, seconds = warm_frames(load(folder, scene_yaml(sky, LAMP.format(motion=motion), spp=spp, blur="off"), f"{len(out)}.yaml"), list(range(frames + 1)))
        rms = statistics.mean(float(np.sqrt(np.mean((img - ref) ** 2))) for img in images)
        out[label] = {"warm_s": statistics.median(seconds), "rms_error": rms}
    return out


def ground_stats(rgb: np.ndarray, up: np.ndarray) -> tuple[float, float]:
    """Mean luminance of the ground pixels and their 90th / 10th percentile ratio."""
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722])
    ground = lum[up]
    p10, p90 = np.percentile(ground, [10, 90])
    return float(ground.mean()), float(p90 / max(p10, 1e-6))


def examples(spp: int) -> list[dict[str, Any]]:
    """Each example at a third of its shot, ours vs `path` on the same records."""
    import mitsuba as mi

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.render.poses.stacked import stack_frame
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    rows = []
    for path in sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.yaml")):
        overrides = {"render": {"resolution": [192, 108], "spp": spp, "motion_blur": "off"}, "output": {"aovs": ["normal"]}}
        loaded = load_scene(path, overrides)
        tl = loaded.scene.timeline
        frame = tl.first + (tl.last - tl.first) // 3
        gc.collect()
        renderer = FrameRenderer(loaded)
        (fi,) = evaluate_frames(loaded, [frame])
        ours, aovs, _ = renderer.render_layers(fi)
        up = aovs["N"][..., 1] > 0.9
        ref = np.array(mi.render(renderer._full_scene(stack_frame(fi), None), seed=7, spp=spp))[..., :3]
        o_mean, o_contrast = ground_stats(ours[..., :3], up)
        r_mean, r_contrast = ground_stats(ref, up)
        rows.append({"scene": path.stem, "frame": frame, "ground_px": int(up.sum()), "ours_mean": o_mean, "path_mean": r_mean, "ours_contrast": o_contrast, "path_contrast": r_contrast})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer frames and samples")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    parser.add_argument("--examples", action="store_true", help="also check the example shots (section 4)")
    args = parser.parse_args()
    from motion.pipeline import variant

    chosen = variant.activate("auto", quiet=True).variant
    spp = 64 if args.quick else 256
    frames = 3 if args.quick else 8
    print(f"# lights benchmark: {cpu_model()}, {chosen}, {RES[0]}x{RES[1]}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rows = agreement(folder, spp)
        print(f"\n## mean of the frame, ours vs Mitsuba path ({spp} spp)\n")
        print("| light | ours | Mitsuba `path` | ours / path |\n|---|---|---|---|")
        for r in rows:
            print(f"| {r['light']} | {r['ours']:.4f} | {r['path']:.4f} | {r['ratio']:.3f} |")
        cost = costs(folder, 16, frames)
        base_point = cost["point light, still"]["warm_s"]
        base_area = cost["area light 0.3 m, static set"]["warm_s"]
        print(f"\n## cost at 16 spp (median warm frame of {frames})\n")
        print("| case | warm frame (s) | vs still | RMS error vs 1024-spp reference |\n|---|---|---|---|")
        for label, v in cost.items():
            base = base_point if label.startswith("point") else base_area
            err = f"{v['rms_error']:.4f}" if "rms_error" in v else ""
            print(f"| {label} | {v['warm_s']:.3f} | {v['warm_s'] / base:.2f}x | {err} |")
    shots: list[dict[str, Any]] = []
    if args.examples:
        shots = examples(spp)
        print(f"\n## example shots: the ground, ours vs Mitsuba path ({spp} spp, 192x108, blur off)\n")
        print("| scene | frame | ground mean, ours | path | lit/shadow contrast, ours | path |\n|---|---|---|---|---|---|")
        for r in shots:
            print(f"| {r['scene']} | {r['frame']} | {r['ours_mean']:.4f} | {r['path_mean']:.4f} | {r['ours_contrast']:.2f} | {r['path_contrast']:.2f} |")
    if args.json:
        args.json.write_text(json.dumps({"cpu": cpu_model(), "variant": chosen, "agreement": rows, "cost": cost, "examples": shots}, indent=2))


if __name__ == "__main__":
    sys.exit(main())
