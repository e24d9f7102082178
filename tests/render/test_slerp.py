"""One slerp (motion/pose.py `slerp_with`): the render kernel's (drjit, float32) and the
host's (numpy, float64) are the same formula on two array libraries, so a pose the kernel
interpolates at a path's time is the pose the host computes for the same shutter fraction
(`shutter.resample`: sub-frames, the scalar fallback), to float32 rounding."""

from __future__ import annotations

import numpy as np
import pytest

from _render_support import activate

pytestmark = pytest.mark.render


def test_the_kernels_slerp_is_the_hosts() -> None:
    activate()
    import mitsuba as mi

    from motion.pipeline.motion.pose import quat_mul, quat_normalize, slerp as host
    from motion.pipeline.render.poses.kernel import slerp as kernel

    rng = np.random.default_rng(5)
    q0 = quat_normalize(rng.normal(size=(400, 4)))
    turn = quat_normalize(np.concatenate([np.ones((400, 1)), rng.normal(size=(400, 3)) * np.geomspace(1e-7, 3.0, 400)[:, None]], axis=1))
    q1 = quat_mul(turn, q0)  # from nearly the same rotation (the lerp branch) to far apart
    q1[::3] *= -1  # the other hemisphere: the shortest path flips it
    f = rng.uniform(0, 1, 400)
    want = host(q0, q1, f)
    got = kernel(mi.Vector4f(*(mi.Float(q0[:, k].astype(np.float32)) for k in range(4))),
                 mi.Vector4f(*(mi.Float(q1[:, k].astype(np.float32)) for k in range(4))), mi.Float(f.astype(np.float32)))
    got = np.stack([np.array(got[k]) for k in range(4)], axis=1)
    same = np.where(np.sum(got * want, axis=1, keepdims=True) < 0, -got, got)  # q and -q are one rotation
    np.testing.assert_allclose(same, want, atol=3e-6)
