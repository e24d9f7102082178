"""Frames numbered below 0 are read whole by `motion export` and `motion view`."""

from __future__ import annotations

from pathlib import Path

from _scenes import TWO_FRAMES as BASE
from farm_util import motion


def test_export_of_frames_below_zero_is_whole(tmp_path: Path) -> None:
    """Frames below 0 are read by every tool: export and view write all four images (before
    the reader ignored them: 2 of 4 images, exit 0; then they were refused)."""
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("first: 0, last: 1", "first: -2, last: 1"))
    assert motion("render", scene, "-o", tmp_path / "out").returncode == 0
    for command in ("export", "view"):
        res = motion(command, tmp_path / "out", "-o", tmp_path / command / "index.html" if command == "view" else tmp_path / command)
        assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "export").glob("*.png"))[:2] == ["s.-0001.png", "s.-0002.png"]
    assert len(list((tmp_path / "export").glob("*.png"))) == 4 and len(list((tmp_path / "view" / "frames").glob("*.jpg"))) == 4
