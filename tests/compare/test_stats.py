"""The noise test of one frame (pipeline/compare/stats.py) on frames whose noise is known:
independent noise of a known level, edges whose coverage is drawn from 4 samples over a
noise-free sky (a block's noise in a few pixels), and planted changes."""

from __future__ import annotations

import numpy as np

from motion.pipeline.compare.stats import FILTER_KAPPA, compare_frame

H, W = 36, 64


def _discs(rng: np.random.Generator) -> np.ndarray:
    """Three bright discs over a constant sky, their edge pixels' coverage from 4 samples
    (the sky itself has no noise at all), stored as half floats."""
    img = np.full((H, W, 4), 0.5, np.float32)
    img[..., 3] = 1
    yy, xx = np.mgrid[0:H, 0:W]
    for cx, cy, r in ((12, 10, 6.5), (40, 18, 9.3), (55, 6, 4.2)):
        dist = np.hypot(xx - cx, yy - cy) - r
        cover = np.where(np.abs(dist) < 0.7, rng.binomial(4, np.clip(0.5 - dist, 0, 1)) / 4.0, (dist < 0).astype(float))
        img[..., :3] = img[..., :3] * (1 - cover[..., None]) + 0.9 * cover[..., None]
    return img.astype(np.float16).astype(np.float32)


def test_noise_in_a_few_edge_pixels_is_no_alarm() -> None:
    """A block that an edge only nicks has its variance from a handful of pixels: its t has
    few degrees of freedom (before they were counted: 1 alarm in these 300, |z| 6.9)."""
    rng = np.random.default_rng(5)
    results = [compare_frame(_discs(rng), _discs(rng), kappa=FILTER_KAPPA["box"]) for _ in range(300)]
    assert sum(r.verdict == "different" for r in results) == 0
    assert max(r.max_z for r in results) < 5.0


def test_identical_equal_and_planted_changes() -> None:
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:H, 0:W] / float(H)
    picture = np.stack([0.2 + 0.3 * xx, 0.3 + 0.4 * yy, 0.5 + 0.2 * np.sin(6 * xx), np.ones_like(xx)], axis=2)

    def noisy(p: np.ndarray) -> np.ndarray:
        out = p * (1 + 0.1 * rng.standard_normal(p.shape))
        out[..., 3] = 1
        return out.astype(np.float32)

    ref = noisy(picture)
    assert compare_frame(ref, ref.copy()).verdict == "identical"
    assert all(compare_frame(noisy(picture), noisy(picture), kappa=1.1).verdict == "equal" for _ in range(50))
    changed = picture.copy()
    changed[8:20, 40:56, 2] *= 1.25  # blue 25% brighter on 8% of the frame
    t = compare_frame(noisy(changed), ref, kappa=1.1)
    assert t.verdict == "different"
    worst = t.regions[0]
    assert worst.channel == "B" and worst.mean_diff > 0 and 0.15 < worst.relative < 0.35
    assert worst.x0 <= 40 and worst.x1 >= 56 - 4 and worst.y0 <= 8 + 4 and worst.y1 >= 20 - 4
    dimmer = noisy(picture * np.array([0.9, 0.9, 0.9, 1.0]))  # the whole frame 10% darker
    t = compare_frame(dimmer, ref, kappa=1.1)
    assert t.verdict == "different" and sum(r.fraction for r in t.regions) > 0.5 and all(r.mean_diff < 0 for r in t.regions)
