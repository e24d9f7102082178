"""Our inverse telecine against FFmpeg's own: `fieldmatch` + `decimate` through PyAV's filter graph.

The film frames are small 8-bit pictures of a moving disc over a vertical ramp (smooth
content, like real footage: FFmpeg's field matching judges combing, and on per-pixel noise it
cannot tell a clean weave from a combed one). They go through our telecine (EXR files, half
float, integer values, so exact), then through our inverse telecine (from our metadata, and by
detection alone) and through FFmpeg's filters; both must give back the film frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.frame_output import read_frame, write_frame
from motion.pipeline.telecine.convert import inverse_sequence, telecine_sequence
from motion.pipeline.telecine.inverse import inverse_frames
from motion.pipeline.telecine.reference import ffmpeg_inverse_telecine

H, W, N = 48, 64, 12


def disc_film(n: int = N) -> list[np.ndarray]:
    """n distinct uint8 [H, W] frames: a disc moving 3 px right per frame over a vertical ramp."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    return [np.round(np.where((x - (8 + 3 * i)) ** 2 + (y - 24) ** 2 < 100, 200.0, 30.0) + y / 2).astype(np.uint8)
            for i in range(n)]


def which(frame: np.ndarray, film: list[np.ndarray]) -> int | None:
    """The film frame `frame` is bit for bit, or None (a combed or altered frame)."""
    return next((i for i, f in enumerate(film) if np.array_equal(f, frame)), None)


def telecined(tmp_path: Path, film: list[np.ndarray], pattern: str, order: str) -> list[np.ndarray]:
    """Our telecine of `film`, through EXR files: the video frames' luma as uint8 (exact)."""
    for i, luma in enumerate(film):
        rgba = np.ones((H, W, 4), np.float32)
        rgba[..., :3] = luma[..., None]
        write_frame(tmp_path / "film" / f"disc.{i + 1:04d}.exr", rgba)
    tele = telecine_sequence(tmp_path / "film", tmp_path / "60i", pattern=pattern, field_order=order)
    video = [read_frame(p).rgba[..., 0] for p in tele.paths]
    assert all(np.array_equal(v, v.astype(np.uint8)) for v in video)
    return [v.astype(np.uint8) for v in video]


@pytest.mark.parametrize("pattern", ["3:2", "2:3:3:2"])
@pytest.mark.parametrize("order", ["tff", "bff"])
def test_whole_cycles_agree_bit_for_bit(tmp_path: Path, pattern: str, order: str) -> None:
    film = disc_film()
    video = telecined(tmp_path, film, pattern, order)
    assert len(video) == 15  # 12 film frames, 3 cycles
    theirs = ffmpeg_inverse_telecine(video, order)
    back = inverse_sequence(tmp_path / "60i", tmp_path / "24p")  # from our metadata
    from_meta = [read_frame(p).rgba[..., 0] for p in back.paths]
    detected, found = inverse_frames([v.astype(np.float32) for v in video], order)  # type: ignore[arg-type]
    assert found.cadence.name == pattern and found.phase == 0
    assert len(theirs) == len(from_meta) == len(detected) == N
    for k in range(N):
        np.testing.assert_array_equal(theirs[k], film[k])
        np.testing.assert_array_equal(from_meta[k], film[k].astype(np.float32))
        np.testing.assert_array_equal(detected[k], film[k].astype(np.float32))


@pytest.mark.parametrize("pattern", ["3:2", "2:3:3:2"])
def test_clip_cut_mid_cycle(tmp_path: Path, pattern: str) -> None:
    """Without the first video frame: we find the phase and return film frames 1..11 once each.

    `decimate` drops one frame in every 5 counted from the clip's first frame; 14 frames are
    two full cycles and a partial one of 4 that it leaves whole, so FFmpeg's output is the
    same film frames in the same order, bit for bit, with one of them twice.
    """
    film = disc_film()
    video = telecined(tmp_path, film, pattern, "tff")[1:]
    ours, found = inverse_frames([v.astype(np.float32) for v in video], "tff")
    assert found.phase == 2
    assert [which(f.astype(np.uint8), film) for f in ours] == list(range(1, N))
    theirs = [which(f, film) for f in ffmpeg_inverse_telecine(video, "tff")]
    assert None not in theirs  # every output frame is a film frame bit for bit, none combed
    assert list(dict.fromkeys(theirs)) == list(range(1, N))  # same selection, same order
    assert len(theirs) == N  # ... plus one duplicate in the partial last cycle
    assert sorted(theirs) == theirs
