"""Every `--deliver` check that can fail runs before the first frame is rendered."""

from __future__ import annotations

import pytest

from farm_util import SCENE, frames_in, motion


@pytest.mark.parametrize(
    "args,message",
    [
        (["--preset", "ci-smoke", "--deliver", "24p"], "gapless"),  # ci-smoke spreads 3 frames over the timeline
        (["--frames", "0-3", "--resolution", "16x11", "--deliver", "60i"], "even height"),
        (["--frames", "0-3", "--deliver", "24p", "--ocio", "/no/such/config.ocio"], "config"),
    ],
)
def test_every_deliver_check_runs_before_the_first_frame(tmp_path, args, message) -> None:
    res = motion("render", SCENE, "-o", tmp_path, "--no-progress", *args)
    assert res.returncode == 2, res.stderr
    assert message in res.stderr and "Traceback" not in res.stderr
    assert frames_in(tmp_path) == []
