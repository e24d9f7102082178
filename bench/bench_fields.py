"""Field rendering cost (not a timed test): `python bench/bench_fields.py [WxH] [spp]`.

One process renders frames of scenes/stairs-walk.yaml progressively and the same frames
as single fields (`render_layers(field=)`: only every other row), alternating, after
a warm-up of each kind (kernels compiled). A 60i field should cost about half a
progressive frame: half the pixels, the same scene. Prints the median seconds of each and
the ratio, with the CPU model.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_flock import cpu_name  # noqa: E402

from motion.pipeline import variant  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def main(resolution: tuple[int, int] = (320, 180), spp: int = 16, frames: int = 6) -> None:
    variant.activate("auto", quiet=True)
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.scene import load_scene

    loaded = load_scene(REPO / "scenes" / "stairs-walk.yaml", {"render": {"resolution": list(resolution), "spp": spp}})
    inputs = evaluate_frames(loaded, list(range(20, 20 + frames)))
    renderer = FrameRenderer(loaded)
    renderer.render(inputs[0])  # warm-up: build and compile (progressive)
    renderer.render_layers(inputs[0], field="top")  # and the field kernels
    full, field, full_r, field_r = [], [], [], []
    for fi in inputs:
        t0 = time.perf_counter()
        img, st = renderer.render(fi)
        full.append(time.perf_counter() - t0)
        full_r.append(st.render_s)
        t0 = time.perf_counter()
        half, _, st = renderer.render_layers(fi, field="bottom" if fi.frame % 2 else "top")
        field.append(time.perf_counter() - t0)
        field_r.append(st.render_s)
        assert half.shape[0] == img.shape[0] // 2
    a, b = float(np.median(full)), float(np.median(field))
    ar, br = float(np.median(full_r)), float(np.median(field_r))
    print(f"CPU: {cpu_name()}; {resolution[0]}x{resolution[1]}, {spp} spp, {frames} frames each, one process")
    print(f"whole call:   progressive frame {a:.3f} s, one field {b:.3f} s, field / frame = {b / a:.2f}")
    print(f"render alone: progressive frame {ar:.3f} s, one field {br:.3f} s, field / frame = {br / ar:.2f}")


if __name__ == "__main__":
    res = tuple(int(v) for v in sys.argv[1].split("x")) if len(sys.argv) > 1 else (320, 180)
    main(res, int(sys.argv[2]) if len(sys.argv) > 2 else 16)  # type: ignore[arg-type]
