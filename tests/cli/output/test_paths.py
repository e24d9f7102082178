"""Output paths given on the command line: an empty one is refused, never read as the
current folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import motion


@pytest.mark.parametrize("argv", [
    ["render", "{scene}", "-o", ""],
    ["render", "{scene}", "-o", "  "],
    ["render", "{scene}", "--report", ""],
    ["bake", "{scene}", "-o", ""],
    ["telecine", "{tmp}", "-o", ""],
])
def test_an_empty_output_path_is_refused_not_the_current_folder(tmp_path: Path, argv: list[str]) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    work = tmp_path / "cwd"
    work.mkdir()
    res = motion(*[a.format(scene=scene, tmp=tmp_path) for a in argv], cwd=work)
    assert res.returncode == 2 and "an empty path" in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert not os.listdir(work)  # before: frames and report in the current folder, exit 0
