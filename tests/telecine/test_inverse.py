"""Inverse telecine (telecine/inverse.py): pulldown and back is bit-exact, the pattern is
detected without metadata (in memory and on EXR files), and the blend variant."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from _telecine_frames import H, W, write_seq
from motion.pipeline.field_model import weave_frames
from motion.pipeline.frame_output import read_frame, write_frame
from motion.pipeline.telecine.cadence import parse_cadence, plan
from motion.pipeline.telecine.convert import inverse_sequence, telecine_sequence
from motion.pipeline.telecine.inverse import inverse_frames
from motion.pipeline.telecine.reference import ffmpeg_telecine


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
