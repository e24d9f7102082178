"""An `--ocio` config path that is not a regular file is refused, never waited on."""

from __future__ import annotations

import os
from pathlib import Path

from _scenes import TWO_FRAMES as BASE
from farm_util import motion


def test_an_ocio_config_that_is_not_a_regular_file_is_refused_not_waited_on(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    fifo = tmp_path / "config.ocio"
    os.mkfifo(fifo)
    for config, why in ((fifo, "not a regular file"), (tmp_path, "is a folder")):
        res = motion("render", scene, "-o", tmp_path / "out", "--deliver", "review", "--ocio", config, timeout=60)  # before: hung in OCIO's reader
        assert res.returncode == 2 and why in res.stderr and "OCIO config" in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()
