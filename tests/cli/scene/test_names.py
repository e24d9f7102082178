"""Names of objects and scene files map to safe file and Mitsuba object names."""

from __future__ import annotations

from pathlib import Path

import pytest

from _scenes import BASE


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_names_map_to_safe_file_and_object_names(tmp_path: Path) -> None:
    """An object named `a.b` (or a glTF node named like its file) rendered nothing before:
    Mitsuba reserves '.' in its object paths; a scene file `.x.yaml` wrote hidden frames."""
    from farm_util import motion

    (tmp_path / ".x.yaml").write_text(BASE.replace("render: {", "render: {variant: auto, ").replace(", variant: scalar_rgb", "").replace("name: ball", "name: a.b")
                                     + "  - {name: a_b, shape: cube, size: 0.3, motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: [0, 0, 0]}, {time: 1, value: [1, 0, 0]}]}}}}\n"
                                     + "  - {name: c.d, shape: sphere, radius: 0.2, motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: [0, 1, 0]}, {time: 1, value: [1, 1, 0]}]}}}}\n")
    res = motion("render", tmp_path / ".x.yaml", "-o", tmp_path / "out", "--no-progress")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "out").glob("*.exr")) == ["x.0000.exr", "x.0001.exr", "x.0002.exr"]
    # a file named `...yaml` once made the name '..' and the pattern '{name}/####.exr' escape -o
    (tmp_path / "...yaml").write_text(BASE + "output: {filename: '{name}/####.exr'}\n")
    res = motion("render", tmp_path / "...yaml", "-o", tmp_path / "dots", "--no-progress")
    assert res.returncode == 0, res.stderr
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.exr") if "dots" in p.parts) == [f"dots/scene/{f:04d}.exr" for f in range(3)]
