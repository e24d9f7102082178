"""Text that cannot be encoded (a lone surrogate in a scene's string, a file or folder name
that is not UTF-8) is a located error before any frame."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import motion


@pytest.mark.parametrize("extra, where", [
    ('output: {owner: "ann\\ud800"}\n', "7:17: output.owner"),
    ('output: {comments: "x\\udfff y"}\n', "7:20: output.comments"),
    ('output: {directory: "out\\udc80"}\n', "7:21: output.directory"),
    ('"extra\\ud800": 1\n', "7:1: extra\\ud800"),
])
def test_a_lone_surrogate_is_a_located_error_at_validation(tmp_path: Path, extra: str, where: str) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE + extra)
    res = motion("validate", scene)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert f"s.yaml:{where}: a lone surrogate" in res.stderr.splitlines()[0], res.stderr
    res = motion("render", scene, "-o", tmp_path / "out")  # before: every frame failed with UnicodeEncodeError
    assert res.returncode == 2 and not (tmp_path / "out").exists(), res.stderr


def test_names_that_are_not_utf8_are_refused_before_any_frame(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    odd = os.fsdecode(b"sc\xffene.yaml")
    (tmp_path / odd).write_text(BASE)
    for argv, what in (([scene, "-o", tmp_path / os.fsdecode(b"out\xff")], "output folder"), ([tmp_path / odd, "-o", tmp_path / "o2"], "scene file")):
        res = motion("render", *argv)
        assert res.returncode == 2 and f"error: {what} " in res.stderr and "\\xff" in res.stderr and "not UTF-8" in res.stderr, res.stderr
    assert sorted(os.listdir(tmp_path)) == sorted(["s.yaml", odd])
