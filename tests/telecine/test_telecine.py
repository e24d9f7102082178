"""Telecine: field model, cadences, FFmpeg agreement, inverse telecine, sequence errors.

Frames encode their own identity: R = film frame index, G = row, B = column (all exact
in half float), so every output field can be traced to its source frame and rows.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.errors import FrameIOError, UsageError
from motion.pipeline.frame_output import read_frame, read_header, timecode_str, write_frame
from motion.pipeline.telecine.cadence import field_sources, output_rate, parse_cadence, plan
from motion.pipeline.telecine.convert import inverse_sequence, telecine_sequence
from motion.pipeline.field_model import field, split, weave, weave_frames
from motion.pipeline.telecine.inverse import inverse_frames
from motion.pipeline.telecine.reference import ffmpeg_telecine
from motion.pipeline.telecine.sequence import discover

H, W = 24, 32


def ident(i: int, h: int = H, w: int = W) -> np.ndarray:
    """A frame that encodes its index and each pixel's row and column."""
    rgba = np.empty((h, w, 4), np.float32)
    rgba[..., 0] = i
    rgba[..., 1] = np.arange(h)[:, None]
    rgba[..., 2] = np.arange(w)[None, :]
    rgba[..., 3] = 1
    return rgba


def write_seq(folder: Path, n: int, first: int = 1, name: str = "shot", fps: int = 24) -> Path:
    for i in range(n):
        write_frame(folder / f"{name}.{first + i:04d}.exr", ident(i), {"frame": first + i, "spp": 4}, fps=Fraction(fps))
    return folder


# Documented tables (top, bottom) for A B C D = 0 1 2 3, top field first.
TABLES = {
    "3:2": [(0, 0), (1, 1), (1, 2), (2, 3), (3, 3)],
    "2:3:3:2": [(0, 0), (1, 1), (1, 2), (2, 2), (3, 3)],
    "2:2": [(0, 0), (1, 1), (2, 2), (3, 3)],
}


def test_field_split_and_weave_are_inverse() -> None:
    frame = ident(7)
    top, bottom = split(frame)
    assert top.shape == (H // 2, W, 4) and np.shares_memory(top, frame)
    assert (top[..., 1][:, 0] == np.arange(0, H, 2)).all()
    assert (bottom[..., 1][:, 0] == np.arange(1, H, 2)).all()
    assert np.array_equal(weave(top, bottom), frame)
    odd = np.arange(5 * 3).reshape(5, 3)
    assert np.array_equal(weave(*split(odd)), odd)
    mixed = weave_frames(ident(1), ident(2))
    assert (field(mixed, "top")[..., 0] == 1).all() and (field(mixed, "bottom")[..., 0] == 2).all()


@pytest.mark.parametrize("pattern", sorted(TABLES))
@pytest.mark.parametrize("order", ["tff", "bff"])
def test_cadence_tables(pattern: str, order: str) -> None:
    frames = plan(4, parse_cadence(pattern), order)  # type: ignore[arg-type]
    assert [(v.top, v.bottom) for v in frames] == (
        TABLES[pattern] if order == "tff" else [(b, t) for t, b in TABLES[pattern]]
    )
    # Fields in time order: the first field has the order's parity.
    sources = field_sources(4, parse_cadence(pattern))
    assert [s for v in frames for s in (v.first, v.second)] == sources
    assert len(sources) == (10 if pattern != "2:2" else 8)


def test_cadence_rates_and_general_strings() -> None:
    assert output_rate(Fraction(24000, 1001), parse_cadence("3:2")) == Fraction(30000, 1001)
    assert output_rate(Fraction(24), parse_cadence("2:3:3:2")) == 30
    assert output_rate(Fraction(25), parse_cadence("2:2")) == 25
    # 24p -> 50i "Euro pulldown": 11 frames of 2 fields and one of 3, twice: 24 -> 25.
    euro = parse_cadence("222222222223")
    assert output_rate(Fraction(24), euro) == 25
    assert parse_cadence("32").counts == (3, 2)
    with pytest.raises(UsageError, match="unknown pulldown"):
        parse_cadence("3-2")


@pytest.mark.parametrize("n,pad,drop", [(5, 6, 6), (6, 8, 7), (7, 9, 8), (3, 4, 3), (1, 1, 1)])
def test_partial_tails(n: int, pad: int, drop: int) -> None:
    cad = parse_cadence("3:2")
    padded, dropped = plan(n, cad, "tff", "pad"), plan(n, cad, "tff", "drop")
    assert (len(padded), len(dropped)) == (pad, drop)
    # pad: every film frame appears in both parities of some frame.
    assert {v.top for v in padded} == {v.bottom for v in padded} == set(range(n))


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


@pytest.mark.parametrize("pattern", ["3:2", "2:3:3:2", "2:2"])
@pytest.mark.parametrize("order", ["tff", "bff"])
def test_round_trip_bit_exact(tmp_path: Path, pattern: str, order: str) -> None:
    rng = np.random.default_rng(1)
    src = tmp_path / "in"
    n = 10
    originals = {}
    for i in range(n):
        rgba = rng.standard_normal((H, W, 4)).astype(np.float16)
        originals[1001 + i] = rgba
        write_frame(src / f"cannonball.{1001 + i:04d}.exr", rgba, aovs={"depth": rng.random((H, W))})
    tele = telecine_sequence(src, tmp_path / "60i", pattern=pattern, field_order=order)
    back = inverse_sequence(tele.out_dir, tmp_path / "24p")
    assert [p.name for p in back.paths] == [f"cannonball.{k:04d}.exr" for k in originals]
    for path, (number, rgba) in zip(back.paths, originals.items()):
        frame = read_frame(path)
        assert np.array_equal(frame.rgba.astype(np.float16).view(np.uint16), rgba.view(np.uint16))
        np.testing.assert_array_equal(frame.aovs["depth"], read_frame(src / path.name).aovs["depth"])
    assert back.rate == Fraction(24000, 1001)


@pytest.mark.parametrize("pattern", ["3:2", "2:3:3:2"])
@pytest.mark.parametrize("order", ["tff", "bff"])
def test_inverse_detects_pattern_without_metadata(pattern: str, order: str) -> None:
    rng = np.random.default_rng(2)
    film = [rng.random((H, W, 3), dtype=np.float32) for _ in range(12)]
    video = [weave_frames(film[v.top], film[v.bottom]) for v in plan(12, parse_cadence(pattern), order)]  # type: ignore[arg-type]
    for start in (0, 1, 3):  # a clip cut mid-cycle
        got, found = inverse_frames(video[start:], order)  # type: ignore[arg-type]
        assert found.cadence.counts == parse_cadence(pattern).counts
        first = next(i for i, f in enumerate(film) if np.array_equal(f, got[0]))
        assert all(np.array_equal(g, film[first + k]) for k, g in enumerate(got))
        assert first + len(got) == 12


def test_inverse_detection_on_exr_files(tmp_path: Path) -> None:
    """Frames with no telecine metadata (e.g. from another tool): detect and recover."""
    rng = np.random.default_rng(3)
    film = [rng.random((H, W, 4), dtype=np.float32).astype(np.float16).astype(np.float32) for _ in range(8)]
    for i, ref in enumerate(ffmpeg_telecine(film, "2332", "bff")):
        write_frame(tmp_path / "v" / f"x.{i:04d}.exr", ref)
    back = inverse_sequence(tmp_path / "v", tmp_path / "p", field_order="bff")
    assert back.detection is not None and back.detection.cadence.counts == (2, 3, 3, 2)
    assert len(back.paths) == 8
    for path, ref in zip(back.paths, film):
        np.testing.assert_array_equal(read_frame(path).rgba, ref)


def test_blend_variant_is_progressive_average(tmp_path: Path) -> None:
    res = telecine_sequence(write_seq(tmp_path / "in", 4), tmp_path / "blend", pattern="blend")
    reds = [float(read_frame(p).rgba[0, 0, 0]) for p in res.paths]
    assert reds == [0.0, 1.0, 1.5, 2.5, 3.0]  # repeat, repeat, blend, blend, repeat
    assert read_frame(res.paths[2]).meta["fieldOrder"] == "progressive"


# --- sequence problems: clear errors naming the frame, nothing written ---------------------


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
