"""Exact time: doctests of the timeline module, plus shutter and timecode properties."""

from __future__ import annotations

import doctest
from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from motion.pipeline import timeline
from motion.pipeline.timeline import Timeline, parse_fps, timecode


def test_doctests() -> None:
    result = doctest.testmod(timeline)
    assert result.attempted > 5 and result.failed == 0


@pytest.mark.parametrize("bad", [0, -24, "0/1", "24/0", "abc", True, "1/-2"])
def test_parse_fps_rejects(bad: object) -> None:
    with pytest.raises(ValueError):
        parse_fps(bad)  # type: ignore[arg-type]


@given(
    fps=st.sampled_from([Fraction(24), Fraction(25), Fraction(30000, 1001), Fraction(24000, 1001), Fraction(60)]),
    frame=st.integers(-1000, 100000),
    angle=st.integers(1, 360),
)
def test_shutter_length_and_position(fps: Fraction, frame: int, angle: int) -> None:
    tl = Timeline(fps, 0, 10)
    for pos in ("start", "center", "end"):
        lo, hi = tl.shutter(frame, angle, pos)  # type: ignore[arg-type]
        assert hi - lo == Fraction(angle, 360) / fps
    assert tl.shutter(frame, angle, "start")[0] == tl.seconds(frame)
    assert tl.shutter(frame, angle, "end")[1] == tl.seconds(frame)
    lo, hi = tl.shutter(frame, angle, "center")
    assert (lo + hi) / 2 == tl.seconds(frame)


def test_drop_frame_timecode_skips_labels() -> None:
    fps = Fraction(30000, 1001)
    assert timecode(1799, fps, drop_frame=True) == "00:00:59;29"
    assert timecode(1800, fps, drop_frame=True) == "00:01:00;02"  # ;00 and ;01 are skipped
    # one hour of real time is 107892 frames at 29.97 and is labelled exactly 01:00:00;00
    assert timecode(107892, fps, drop_frame=True) == "01:00:00;00"
