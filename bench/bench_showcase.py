"""What a viewer sees of the showcase shot (`make render`): clipped pixels under the
deliverables' view, the static horizon's shimmer from frame to frame, and how long the
cannonball is in frame (issue 23).

    python bench/bench_showcase.py                     # reads out/cannonball-splash (make render first)
    python bench/bench_showcase.py --frames DIR --scene scenes/cannonball-splash.yaml

- clipped: share of pixels with a channel at the display's maximum, under the default view
  (OCIO ACES 2.0 SDR) and under the plain sRGB curve (`--ocio none`), all frames and the
  sky's top tenth; and the sky's colour on the display (mean of max - min of R, G, B over
  the top 35% of the image: 0 is grey);
- shimmer: per-pixel standard deviation (of 255) over the frames before the ball lands
  (nothing moves there but the noise), by band of rows: sky, horizon, open water;
- the ball: frames in which its centre is inside the image (from the bake and the camera),
  and its diameter in pixels at frames 20, 30 and the last before landing.
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def ball_in_frame(scene: Path, last: int) -> tuple[list[int], list[float]]:
    """Frames 0..last with the ball's centre inside the image, and its diameter (px) per frame."""
    from motion.pipeline.bake import bake
    from motion.pipeline.scene import load_scene

    loaded = load_scene(scene)
    cam = loaded.scene.camera
    w, h = loaded.scene.render.resolution
    c, look = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
    fwd = (look - c) / np.linalg.norm(look - c)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    k = (w / 2) / np.tan(np.radians(cam.fov / 2))
    radius = next(o.radius for o in loaded.scene.objects if o.name == "ball")
    baked = bake(loaded, list(range(0, last + 1)))
    inside, sizes = [], []
    for f in range(last + 1):
        d = baked.frame(f).at_frame.objects["ball"].translation[0] - c
        z = d @ fwd
        u, v = w / 2 + k * (d @ right) / z, h / 2 - k * (d @ up) / z
        sizes.append(2 * radius * k / z)
        if z > 0 and 0 <= u < w and 0 <= v < h:
            inside.append(f)
    return inside, sizes


def main() -> None:
    """Measure and print."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=Path, default=ROOT / "out" / "cannonball-splash")
    ap.add_argument("--scene", type=Path, default=ROOT / "scenes" / "cannonball-splash.yaml")
    ap.add_argument("--landing", type=int, default=42, help="the frame the ball lands (the scene's header says 42)")
    args = ap.parse_args()
    from motion.pipeline.frame_output import read_frame
    from motion.pipeline.telecine.movie import ViewTransform

    paths = sorted(glob.glob(str(args.frames / "cannonball-splash.*.exr")))
    if not paths:
        print(f"bench_showcase: skipped: no frames in {args.frames} (run `make render` first)")
        return
    frames = [read_frame(p).rgba for p in paths]
    print(f"# showcase {args.frames} ({len(frames)} frames), {cpu_model()}")
    for label, view in (("default view (ACES 2.0 SDR)", ViewTransform()), ("plain sRGB (--ocio none)", ViewTransform(ocio_config="none"))):
        every = np.mean([(view.encode(f) >= 1 - 1e-6).any(axis=-1).mean() for f in frames])
        top = np.mean([(view.encode(f[: max(1, f.shape[0] // 10)]) >= 1 - 1e-6).any(axis=-1).mean() for f in frames])
        # the sky's colour: its chroma on the display, max - min of R, G, B (of 255), top 35%
        chroma = np.mean([np.ptp(view.encode(f[: int(0.35 * f.shape[0])]), axis=-1).mean() for f in frames]) * 255
        print(f"clipped, {label:28}: {100 * every:5.2f}% of pixels, {100 * top:5.2f}% of the top tenth; sky chroma {chroma:.1f}/255")
    view = ViewTransform()
    still = np.stack([view.encode(f) for f in frames[: args.landing - 12]]) * 255  # before the ball is near the water
    std = still.std(axis=0).mean(axis=-1)
    h = std.shape[0]
    bands = {"sky (top 35%)": (0, int(0.35 * h)), "horizon (35-50%)": (int(0.35 * h), int(0.5 * h)), "open water (50-75%)": (int(0.5 * h), int(0.75 * h))}
    print("shimmer (std over frames, of 255): " + ", ".join(f"{k} {std[a:b].mean():.2f}" for k, (a, b) in bands.items()))
    inside, sizes = ball_in_frame(args.scene, args.landing - 1)
    print(f"ball in frame: {len(inside)} of {args.landing} frames before landing (first {inside[0] if inside else '-'}); "
          f"diameter {sizes[20]:.1f} / {sizes[30]:.1f} / {sizes[-1]:.1f} px at frames 20 / 30 / {args.landing - 1}")


if __name__ == "__main__":
    main()
