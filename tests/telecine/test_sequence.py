"""Input sequences (telecine/sequence.py) and what a conversion refuses: a missing frame is
named, mixed resolutions and an odd height, an unreadable frame leaves nothing half
written, an existing output needs --overwrite."""

from __future__ import annotations

from pathlib import Path

import pytest

from _telecine_frames import W, ident, write_seq
from motion.pipeline.errors import FrameIOError, UsageError
from motion.pipeline.frame_output import write_frame
from motion.pipeline.telecine.convert import telecine_sequence


def test_missing_frame_is_named(tmp_path: Path) -> None:
    src = write_seq(tmp_path / "in", 6)
    (src / "shot.0004.exr").unlink()
    with pytest.raises(FrameIOError, match=r"missing frame .*shot\.0004\.exr"):
        telecine_sequence(src, tmp_path / "out")
    assert not list((tmp_path / "out").glob("*")) if (tmp_path / "out").exists() else True


def test_mixed_resolution_and_odd_height(tmp_path: Path) -> None:
    src = write_seq(tmp_path / "in", 4)
    write_frame(src / "shot.0003.exr", ident(2, 26, W))
    with pytest.raises(FrameIOError, match=r"shot\.0003\.exr: resolution 32x26 differs"):
        telecine_sequence(src, tmp_path / "out")
    odd = tmp_path / "odd"
    for i in range(3):
        write_frame(odd / f"o.{i:04d}.exr", ident(i, 25, W))
    with pytest.raises(FrameIOError, match=r"o\.0000\.exr: odd height 25"):
        telecine_sequence(odd, tmp_path / "out")


def test_unreadable_frame_leaves_nothing_half_written(tmp_path: Path) -> None:
    src = write_seq(tmp_path / "in", 6)
    (src / "shot.0002.exr").write_bytes(b"not an exr")
    with pytest.raises(FrameIOError, match=r"shot\.0002\.exr: not a readable OpenEXR"):
        telecine_sequence(src, tmp_path / "out")
    # Header fine, pixels truncated: fails mid-conversion; the destination stays empty.
    write_seq(src, 6)
    data = (src / "shot.0005.exr").read_bytes()
    (src / "shot.0005.exr").write_bytes(data[: len(data) - 200])
    with pytest.raises(FrameIOError, match=r"shot\.0005\.exr"):
        telecine_sequence(src, tmp_path / "out")
    assert list((tmp_path / "out").iterdir()) == []


def test_existing_output_needs_overwrite(tmp_path: Path) -> None:
    src = write_seq(tmp_path / "in", 8)
    telecine_sequence(src, tmp_path / "out")
    with pytest.raises(UsageError, match="--overwrite"):
        telecine_sequence(src, tmp_path / "out")
    res = telecine_sequence(write_seq(tmp_path / "in4", 4), tmp_path / "out", overwrite=True)
    assert sorted(p.name for p in (tmp_path / "out").glob("*.exr")) == sorted(p.name for p in res.paths)
