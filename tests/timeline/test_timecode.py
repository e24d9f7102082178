"""Timecodes at every documented rate: a frame at 48, 50, 59.94, 60 or 120 frames/s is
written with the time address SMPTE ST 12-1 gives (the frame field counts frame pairs above
30 frames/s, the pair flag marks the second of each pair, drop-frame at 59.94 as at 29.97),
read back to the label it was written from, and a shot at those rates renders every frame.
Expectations are closed forms of the frame number."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from farm_util import frames_in, motion
from _scenes import BASE
from motion.pipeline.frame_output import header_timecode, read_header, write_frame
from motion.pipeline.timeline import frame_timecode, parse_fps, timecode_group

PIXELS = np.zeros((2, 2, 4), np.float32)

# rate as a scene writes it, nominal frames a second, frames per value of the frame field
RATES = [("48", 48, 2), ("50", 50, 2), ("59.94", 60, 2), ("60", 60, 2), ("120", 120, 4), ("119.88", 120, 4), ("47.952", 48, 2)]


def _write(tmp_path: Path, frame: int, fps: Fraction) -> dict:
    drop = fps.denominator == 1001 and round(fps) in (30, 60)
    path = write_frame(tmp_path / f"t.{frame:04d}.exr", PIXELS, fps=fps, timecode=frame_timecode(frame, fps, drop_frame=drop))
    return read_header(path)


@pytest.mark.parametrize("written, nominal, group", RATES)
def test_every_frame_across_a_second_boundary_is_written_with_its_st12_address(tmp_path: Path, written: str, nominal: int, group: int) -> None:
    fps = parse_fps(written)
    assert timecode_group(fps) == group
    sep = ";" if written == "59.94" else ":"
    for frame in range(nominal - 3, nominal + 3):  # before: the frame whose FF reached 30 failed
        header = _write(tmp_path, frame, fps)
        code = header["timeCode"]
        ss, ff = divmod(frame, nominal)
        assert (code.hours, code.minutes, code.seconds, code.frame) == (0, 0, ss, ff // group)
        assert code.fieldPhase == bool(ff % 2)  # the second frame of each pair
        assert code.userData == (ff % group if group > 2 else 0)  # a 4-frame group's place
        assert code.dropFrame == (sep == ";")
        assert header_timecode(header) == f"00:00:{ss:02d}{sep}{ff:02d}"


def test_59_94_drop_frame_counts_pairs_and_drops_the_first_two_pairs_of_a_minute(tmp_path: Path) -> None:
    fps = parse_fps("59.94")
    for frame in range(28, 34):  # the frames that failed from frame 28
        code = _write(tmp_path, frame, fps)["timeCode"]
        assert (code.seconds, code.frame, code.fieldPhase, code.dropFrame) == (0, frame // 2, bool(frame % 2), True)
    # minute 0 keeps all 3600 labels; minute 1 starts at label 04 (pair 2): 4 labels dropped
    last, first = _write(tmp_path, 3599, fps), _write(tmp_path, 3600, fps)
    assert header_timecode(last) == "00:00:59;59" and header_timecode(first) == "00:01:00;04"
    assert (first["timeCode"].minutes, first["timeCode"].frame, first["timeCode"].fieldPhase) == (1, 2, False)
    # ten minutes of real time, 35964 frames (10 x 3600 - 9 x 4), is labelled 00:10:00;00
    assert header_timecode(_write(tmp_path, 35964, fps)) == "00:10:00;00"


@pytest.mark.parametrize("written", ["24", "25", "29.97", "30"])
def test_rates_up_to_30_keep_the_plain_frame_field(tmp_path: Path, written: str) -> None:
    fps = parse_fps(written)
    nominal = round(fps)
    code = _write(tmp_path, 2 * nominal - 1, fps)["timeCode"]
    assert (code.seconds, code.frame, code.fieldPhase, code.userData) == (1, nominal - 1, False, 0)


@pytest.mark.parametrize("written, first", [("59.94", 28), ("50", 29)])
def test_a_shot_above_30_fps_renders_past_its_30th_frame(tmp_path: Path, written: str, first: int) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("fps: 24, first: 0, last: 2", f"fps: {written}, first: {first}, last: {first + 3}"))
    res = motion("render", scene, "-o", tmp_path / "out", "--no-progress")
    assert res.returncode == 0, res.stderr  # before: exit 3, "Cannot set frame field in time code"
    sep = ";" if written == "59.94" else ":"
    labels = [header_timecode(read_header(p)) for p in frames_in(tmp_path / "out")]
    assert labels == [f"00:00:00{sep}{f:02d}" for f in range(first, first + 4)]


def test_a_label_past_30_without_a_rate_is_one_located_error(tmp_path: Path) -> None:
    from motion.pipeline.errors import FrameIOError

    with pytest.raises(FrameIOError, match="00:00:00:45: frame 45 is out of range without a frame rate"):
        write_frame(tmp_path / "t.exr", PIXELS, timecode="00:00:00:45")  # before: RuntimeError from the binding
    assert not (tmp_path / "t.exr").exists()
