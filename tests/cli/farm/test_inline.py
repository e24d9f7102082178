"""Small jobs at the engine's start-up cost (farm/inline.py): the executor is chosen by the
frames' estimated cost."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from farm_util import MOTION, SCENE, TINY, report
from farm_util import _auto


def test_a_small_job_renders_inline_and_a_large_one_on_workers(tmp_path: Path) -> None:
    """The executor is chosen by the frames' estimated cost: 3 tiny frames render in this
    process (no worker spawned), a job estimated at minutes spreads over worker processes,
    and --workers always means processes."""
    from motion.pipeline.shot.render import choose_inline
    from motion.pipeline.shot.request import RenderRequest

    small = {"warm_frame_s": 0.05, "cold_extra_s": 1.0}
    large = {"warm_frame_s": 2.0, "cold_extra_s": 1.0}
    req = RenderRequest(scene=SCENE)
    env = _auto()
    old = os.environ.pop("MOTION_EXECUTOR", None)
    try:
        assert choose_inline(req, small, [0, 1, 2]) and not choose_inline(req, large, list(range(24)))
        assert not choose_inline(RenderRequest(scene=SCENE, workers=2), small, [0, 1, 2])
        assert not choose_inline(RenderRequest(scene=SCENE, scheduler="tcp://x:1"), small, [0, 1, 2])
    finally:
        if old is not None:
            os.environ["MOTION_EXECUTOR"] = old
    res = subprocess.run([MOTION, "render", str(SCENE), "-o", str(tmp_path / "out"), "--frames", "0-2", *TINY], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    rep = report(tmp_path / "out")
    assert rep["executor"]["kind"] == "inline" and len({r["worker"] for r in rep["frames"]}) == 1
