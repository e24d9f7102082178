"""The anchor for bench_startup.py: bouncing-balls' ci-smoke job (3 frames, 64x36, 4 spp,
depth 3) by a plain Python script, as a Mitsuba user would write it: import mitsuba,
load_dict, render x3, write EXR. The balls sit where the bake puts them at frames 0, 48 and
95 (their heights are the bake's, rounded); no motion blur (the plain engine has none).

    python bench/plain/bouncing_balls_smoke.py OUT_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

import mitsuba as mi

mi.set_variant("llvm_ad_rgb")

HEIGHTS = {0: (2.0, 2.0, 2.0), 48: (0.95, 0.31, 0.2), 95: (0.62, 0.2, 0.2)}


def scene(frame: int) -> dict:
    """The frame's scene: floor, three plastic balls, constant sky and a point light."""
    d: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 45, "to_world": mi.ScalarTransform4f().look_at(origin=[0, 1.2, 6], target=[0, 0.8, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 36}, "sampler": {"type": "independent", "sample_count": 4}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.5}},
        "lamp": {"type": "point", "position": [2, 4, 3], "intensity": {"type": "rgb", "value": 40}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(5),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
    }
    for i, (x, color) in enumerate(((-1.2, [0.7, 0.1, 0.1]), (0.0, [0.1, 0.6, 0.15]), (1.2, [0.1, 0.2, 0.7]))):
        d[f"ball{i}"] = {"type": "sphere", "center": [x, HEIGHTS[frame][i], 0], "radius": 0.2,
                         "bsdf": {"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": {"type": "rgb", "value": color}}}
    return d


def main() -> None:
    """Render the three frames into OUT_DIR as EXR files."""
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    for frame in HEIGHTS:
        image = mi.render(mi.load_dict(scene(frame)), seed=frame)
        mi.Bitmap(image).write(str(out / f"plain.{frame:04d}.exr"))


if __name__ == "__main__":
    main()
