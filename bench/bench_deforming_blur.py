"""How near a deforming mesh's blur comes to the shutter's true average: the residual templates' crossfade (issue 44).

    python bench/bench_deforming_blur.py [--slices 1,4,8,17] [--spp 256] [--truth-subframes 64]

The shot: a dark skinned arm (tests/support/_scenes.py SKINNED_ARM, a cube on two bones)
whose lower bone turns 90 degrees in two frames, over a white back, orthographic, 96x96:
within frame 1's 180-degree shutter the elbow turns 22.5 degrees and the arm's tip sweeps
about 9 pixels. A bend is what the fitted rigid track cannot carry, so it is all residual
(render/translate/deforming.py): drawn as `time_slices` templates that a lane picks around
its time. Each count is rendered with stochastic blur at --spp (two seeds: its own noise)
and compared with the shutter's average by sub-frames (`motion_blur: subframes`, 64
instants at 4x the samples), each instant the fitted track at its time and the residual
of the nearest of 17 baked samples: the mean absolute difference per pixel and the worst
4x4 block. `time_slices: 1` draws the frame's residual alone (no blur of the bend).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests" / "support"))
from _common import cpu_model  # noqa: E402
from _scenes import SKINNED_ARM  # noqa: E402

# the lower bone's 90 degrees in two frames (1/12 s) instead of one second
ARM = SKINNED_ARM.replace("{time: 1, euler: [0, 0, 90]}", "{time: 0.0834, euler: [0, 0, 90]}")


def shot(slices: int, blur: str, spp: int, subframes: int = 8, seed: int = 0) -> str:
    """The arm's scene YAML for `time_slices: slices` and `motion_blur: blur`."""
    return f"""
timeline: {{fps: 24, first: 0, last: 2}}
camera: {{type: orthographic, position: [0, 1, -6], look_at: [0, 1, 0], ortho_width: 4, shutter: {{angle: 180}}}}
lights: [{{type: constant, radiance: 1.0}}]
materials: [{{name: arm, type: diffuse, color: [0.05, 0.05, 0.05]}}, {{name: white, type: diffuse, color: 0.9}}]
objects:
  - {{name: back, shape: rectangle, width: 20, height: 20, material: white, transform: {{translate: [0, 0, 5], rotate: {{euler: [0, 180, 0]}}}}}}
{ARM}render: {{resolution: [96, 96], spp: {spp}, max_depth: 2, motion_blur: {blur}, subframes: {subframes}, time_slices: {slices}, shutter_samples: 17, seed: {seed}}}
"""


def render(folder: Path, name: str, text: str) -> np.ndarray:
    """Frame 1's red channel, by one first-frame-cached renderer."""
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.scene import load_scene

    path = folder / f"{name}.yaml"
    path.write_text(text)
    loaded = load_scene(path)
    (frame,) = evaluate_frames(loaded, [1])
    return np.asarray(FrameRenderer(loaded).render(frame)[0][..., 0], dtype=np.float64)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slices", default="1,4,8,17")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--truth-subframes", type=int, default=64)
    args = ap.parse_args()
    from motion.pipeline import variant

    chosen = variant.activate("auto", quiet=True).variant
    folder = Path(tempfile.mkdtemp())
    truth = render(folder, "truth", shot(4, "subframes", args.spp * 4, args.truth_subframes))
    print(f"# bench_deforming_blur: a bending arm (22.5 degrees within the shutter), 96x96, {args.spp} spp, {chosen}; CPU: {cpu_model()}")
    print(f"# against {args.truth_subframes} sub-frames at {args.spp * 4} spp")
    print("| time_slices | mean abs difference | its own noise | worst 4x4 block |")
    print("|---|---|---|---|")
    for count in (int(c) for c in args.slices.split(",")):
        a = render(folder, f"s{count}", shot(count, "stochastic", args.spp))
        b = render(folder, f"s{count}b", shot(count, "stochastic", args.spp, seed=9))
        noise = float(np.abs(a - b).mean() / np.sqrt(2))
        blocks = np.abs((a - truth).reshape(24, 4, 24, 4).mean(axis=(1, 3))).max()
        print(f"| {count} | {np.abs(a - truth).mean():.4f} | {noise:.4f} | {blocks:.3f} |", flush=True)


if __name__ == "__main__":
    main()
