"""Pulldown of EXR sequences (telecine/convert.py): each field's rows are the documented
source's rows, timecodes in drop-frame and exact mode, and the same fields as FFmpeg's
`telecine` filter (telecine/reference.py)."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from _telecine_frames import H, TABLES, W, ident, write_seq
from motion.pipeline.errors import UsageError
from motion.pipeline.field_model import field
from motion.pipeline.frame_output import read_frame, read_header, timecode_str, write_frame
from motion.pipeline.telecine.cadence import field_sources, parse_cadence
from motion.pipeline.telecine.convert import telecine_sequence
from motion.pipeline.telecine.reference import ffmpeg_telecine
from motion.pipeline.telecine.sequence import discover


def test_exr_telecine_fields_exact(tmp_path: Path) -> None:
    """4 film frames -> 5 EXR video frames; each field's rows are the documented source's rows."""
    src = write_seq(tmp_path / "in", 4, first=101)
    res = telecine_sequence(src, tmp_path / "out", pattern="3:2", field_order="tff")
    assert [p.name for p in res.paths] == [f"shot.{n:04d}.exr" for n in range(101, 106)]
    assert res.rate == Fraction(30000, 1001)
    for (top, bottom), path in zip(TABLES["3:2"], res.paths):
        frame = read_frame(path)
        assert frame.header["framesPerSecond"] == Fraction(30000, 1001)
        np.testing.assert_array_equal(field(frame.rgba, "top"), field(ident(top), "top"))
        np.testing.assert_array_equal(field(frame.rgba, "bottom"), field(ident(bottom), "bottom"))
        meta = frame.meta
        assert (meta["topFieldSource"], meta["bottomFieldSource"]) == (101 + top, 101 + bottom)
        assert meta["fieldOrder"] == "tff" and meta["filmSpeed"] == Fraction(24000, 1001)
        assert meta["spp"] == 4  # the source frame's own attributes are carried
    assert read_frame(res.paths[0]).rgba.dtype == np.float32
    assert discover(tmp_path / "out").pixel_type == "half"


def test_timecode_drop_frame_and_exact_mode(tmp_path: Path) -> None:
    src = write_seq(tmp_path / "in", 4)
    res = telecine_sequence(src, tmp_path / "df", drop_frame=True)
    # film frame 1 starts video frame 1 (1 x 30/24, rounded down): video frame 4 is 00:00:00;05
    assert timecode_str(read_header(res.paths[4])["timeCode"]) == "00:00:00;05"
    assert timecode_str(read_header(telecine_sequence(src, tmp_path / "ndf").paths[4])["timeCode"]) == "00:00:00:05"
    exact = telecine_sequence(src, tmp_path / "exact", film_speed="24")
    assert exact.rate == 30 and read_header(exact.paths[0])["framesPerSecond"] == Fraction(30)
    with pytest.raises(UsageError, match="drop-frame"):
        telecine_sequence(src, tmp_path / "bad", film_speed="24", drop_frame=True)
    assert not (tmp_path / "bad").exists() or not list((tmp_path / "bad").glob("*.exr"))


@pytest.mark.parametrize("pattern", ["3:2", "2:3:3:2"])
@pytest.mark.parametrize("order", ["tff", "bff"])
@pytest.mark.parametrize("n", [8, 11])
def test_agrees_with_ffmpeg_telecine(tmp_path: Path, pattern: str, order: str, n: int) -> None:
    """Same EXR input through our telecine and through FFmpeg's filter: identical fields."""
    rng = np.random.default_rng(n)
    src = tmp_path / "in"
    originals = []
    for i in range(n):
        rgba = (ident(i) + rng.random((H, W, 4), dtype=np.float32)).astype(np.float16).astype(np.float32)
        originals.append(rgba)
        write_frame(src / f"r.{i:04d}.exr", rgba)
    ours = telecine_sequence(src, tmp_path / "out", pattern=pattern, field_order=order, tail="drop")
    theirs = list(ffmpeg_telecine(originals, pattern, order))  # type: ignore[arg-type]
    assert len(theirs) == len(ours.paths) == len(field_sources(n, parse_cadence(pattern), "drop")) // 2
    for path, ref in zip(ours.paths, theirs):
        got = read_frame(path).rgba
        for parity in ("top", "bottom"):
            np.testing.assert_array_equal(field(got, parity), field(ref, parity).astype(np.float32))
