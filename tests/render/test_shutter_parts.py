"""The broadphase's parts of the shutter (render/kernel/broadphase.py `parts`, `in_regions`): a
lane at shutter fraction u walks the proxies of its own part, so that part must hold every
sample the lane interpolates between, and no two parts' regions may meet."""

from __future__ import annotations

import numpy as np
import pytest

from motion.pipeline.render.kernel.broadphase import FAR, PARTS, in_regions, parts, particle_proxies, sphere_proxies


@pytest.mark.parametrize("n", [2, 3, 4, 5, 9, 10, 17, 33, 64, 65])
def test_each_part_holds_the_samples_its_lanes_interpolate(n: int) -> None:
    cuts = parts(n)
    assert len(cuts) == min(PARTS, n - 1)
    count = len(cuts)
    for u in np.linspace(0.0, 1.0, 4001):
        b = min(int(np.floor(np.float32(u) * np.float32(count))), count - 1)  # as the kernel, in float32
        i = min(int(np.floor(np.float32(u) * np.float32(n - 1))), n - 2)  # FrameData.segment
        first, last = cuts[b]
        assert first <= i and i + 1 <= last, (n, u, b, cuts[b])


def test_the_regions_never_meet_and_hold_their_parts() -> None:
    rng = np.random.default_rng(2)
    path = np.cumsum(rng.normal(size=(300, 9, 3)), axis=1)  # 300 particles, 9 samples, wandering
    alive = rng.uniform(size=(300, 9)) > 0.2
    per_part = [particle_proxies(path[:, a:b + 1], alive[:, a:b + 1], np.full(300, 0.05)) for a, b in parts(9)]
    per_part[0] = np.concatenate([per_part[0][:-1], sphere_proxies(np.array([[FAR, FAR, FAR, 1e-6]]))])  # one dead proxy stays far
    records, box, spacing = in_regions(per_part)
    assert records.shape == (len(per_part) * 300, 10)
    spans = []
    for b in range(len(per_part)):
        moved = records[b * 300:(b + 1) * 300]
        live = np.abs(moved[:, 0]) < FAR / 2
        half = moved[live, 3:6].max(axis=1)
        lo, hi = (moved[live, 0] - half).min(), (moved[live, 0] + half).max()
        # each region is the world box moved by b spacings along x
        assert box[0, 0] + b * spacing - 1e-6 <= lo and hi <= box[1, 0] + b * spacing + 1e-5 * (1 + b * spacing)
        np.testing.assert_array_equal(moved[live, 1:3], per_part[b][live, 1:3])
        spans.append((lo, hi))
    for (lo_a, hi_a), (lo_b, hi_b) in zip(spans, spans[1:]):
        assert hi_a < lo_b  # regions apart along x
    assert spacing > box[1, 0] - box[0, 0]


def test_parts_are_used_where_they_are_smaller() -> None:
    """A fast particle's proxy per part is an eighth of its streak: worth it. A still one's
    is the same in every part, and eight of them cost each trace deeper BVH levels (4 slow
    movers at the preview preset: 5% of the frame): one part then."""
    from motion.pipeline.render.kernel.broadphase import worth_parts

    fast = np.linspace([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], 9)[None].repeat(50, axis=0)  # 2 m in a shutter, r = 2 cm
    still = np.zeros((50, 9, 3))
    alive, radius = np.ones((50, 9), bool), np.full(50, 0.02)
    for path, worth in ((fast, True), (still, False)):
        whole = particle_proxies(path, alive, radius)
        per_part = [particle_proxies(path[:, a:b + 1], alive[:, a:b + 1], radius) for a, b in parts(9)]
        assert worth_parts(whole, per_part) is worth
