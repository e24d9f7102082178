"""The cache root ($MOTION_CACHE_DIR) and its folders: one that is a file is one line before any work."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from _scenes import BASE


def test_a_cache_folder_that_is_a_file_is_one_line_before_any_work(tmp_path: Path) -> None:
    from farm_util import motion  # noqa: F401  (the real command, with its environment)

    (tmp_path / "scene.yaml").write_text(BASE.replace(", variant: scalar_rgb", ""))
    (tmp_path / "cachefile").write_text("x")
    env = {**os.environ, "MOTION_CACHE_DIR": str(tmp_path / "cachefile")}
    res = subprocess.run([str(Path(sys.executable).with_name("motion")), "render", str(tmp_path / "scene.yaml"), "-o", str(tmp_path / "out"), "--no-progress"],
                         capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 2 and "is a file; point MOTION_CACHE_DIR at a folder" in res.stderr and "Traceback" not in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()
    # a scene that imports a glTF file converts it into the cache while it loads: validate
    # and the dry run (which load before the render's own check) said NotADirectoryError
    # in a traceback
    walker = str(Path(__file__).resolve().parents[3] / "scenes" / "walker.yaml")
    for args in (["validate", walker], ["render", walker, "--dry-run", "-o", str(tmp_path / "out")]):
        res = subprocess.run([str(Path(sys.executable).with_name("motion")), *args], capture_output=True, text=True, env=env, timeout=120)
        assert res.returncode == 2 and "is a file; point MOTION_CACHE_DIR at a folder" in res.stderr and "Traceback" not in res.stderr, res.stderr
