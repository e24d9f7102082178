"""Motion benchmarks (not timed tests): `python bench/bench_motion.py`.

1. evaluate(): 1,000 keyframed objects (catmull-rom translate, catmull-rom rotate,
   linear scale) x 240 frames x 8 sub-frame samples, in one vectorised call.
2. Linear blend skinning: 100k vertices x 4 bones, one frame.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from motion.pipeline.motion import evaluate
from motion.pipeline.motion.deform import linear_blend_skinning, normalise_weights
from motion.pipeline.scene import load_scene


def keyed_scene(count: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    objects = []
    for i in range(count):
        keys_t = [{"time": float(f), "value": rng.uniform(-5, 5, 3).round(3).tolist()} for f in (0, 80, 160, 240)]
        keys_r = [{"time": float(f), "euler": rng.uniform(-180, 180, 3).round(2).tolist()} for f in (0, 80, 160, 240)]
        keys_s = [{"time": 0.0, "value": 1.0}, {"time": 240.0, "value": float(rng.uniform(0.5, 2))}]
        objects.append({
            "name": f"obj{i}", "shape": "cube",
            "motion": {"type": "keyframes", "interpolation": "catmull-rom", "channels": {
                "translate": {"keys": keys_t}, "rotate": {"keys": keys_r},
                "scale": {"keys": keys_s, "interpolation": "linear"}}},
        })
    return {"timeline": {"fps": 24, "first": 0, "last": 239},
            "camera": {"position": [0, 0, 20], "look_at": [0, 0, 0]}, "objects": objects}


def bench_evaluate(count: int = 1000, frames: int = 240, sub: int = 8, repeats: int = 3) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.yaml"
        path.write_text(yaml.safe_dump(keyed_scene(count)))
        loaded = load_scene(path)
    # 8 samples across a 180-degree shutter around each frame
    frame_t = np.arange(frames) / 24.0
    offsets = (np.arange(sub) / (sub - 1) - 0.5) / 48.0
    times = (frame_t[:, None] + offsets[None, :]).ravel()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        motion = evaluate(loaded, times)
        best = min(best, time.perf_counter() - t0)
    assert len(motion.objects) == count and motion.objects["obj0"].translation.shape == (len(times), 3)
    rate = count * len(times) / best
    print(f"evaluate: {count} keyed objects x {frames} frames x {sub} samples = {count * len(times):,} object-samples "
          f"in {best:.3f} s -> {rate:,.0f} samples/s")
    return rate


def bench_skinning(vertices: int = 100_000, bones: int = 4, repeats: int = 5) -> float:
    rng = np.random.default_rng(1)
    v = rng.normal(size=(vertices, 3))
    idx, w = normalise_weights(rng.uniform(0.0, 1.0, (vertices, bones)))
    m = np.tile(np.eye(4)[:3], (1, bones, 1, 1))
    m[0, :, :3, 3] = rng.normal(size=(bones, 3))
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = linear_blend_skinning(v, m, idx, w)
        best = min(best, time.perf_counter() - t0)
    assert out.shape == (1, vertices, 3)
    print(f"skinning: {vertices:,} vertices x {bones} bones, one frame: {best * 1000:.1f} ms "
          f"({vertices / best:,.0f} vertices/s)")
    return best


if __name__ == "__main__":
    bench_evaluate()
    bench_skinning()
