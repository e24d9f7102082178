"""A shot at any frame rate the scene format accepts renders."""

from __future__ import annotations

from pathlib import Path

from _scenes import BASE


def test_a_frame_at_a_rate_under_one_fps_renders(tmp_path: Path) -> None:
    """`fps: 0.001` failed every frame (exit 3: timecode divided by its nominal rate, 0)."""
    from farm_util import motion

    (tmp_path / "slow.yaml").write_text(BASE.replace("fps: 24", "fps: 0.001").replace(", variant: scalar_rgb", ""))
    res = motion("render", tmp_path / "slow.yaml", "-o", tmp_path / "out", "--no-progress")
    assert res.returncode == 0, res.stderr
    assert len(list((tmp_path / "out").glob("*.exr"))) == 3
