"""Telecine deliverables: real movie files decoded with PyAV, contact sheets, the CLI, deliver()."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import matplotlib.image
import numpy as np
import pytest
from click.testing import CliRunner

from motion.cli.main import cli, main
from motion.pipeline.errors import FrameIOError, UsageError
from motion.pipeline.frame_output import read_frame, write_frame
from motion.pipeline.telecine import deliver, parse_formats
from motion.pipeline.telecine.contact_sheet import box_resize, contact_sheet, sheet_layout
from motion.pipeline.telecine.convert import telecine_sequence
from motion.pipeline.telecine.movie import ViewTransform, sequence_movie, srgb_encode
from motion.pipeline.telecine.sequence import discover

H, W = 24, 32
AV_FIELD_TT, AV_FIELD_BB, AV_FIELD_PROGRESSIVE = 2, 3, 1


def grey_seq(folder: Path, n: int, name: str = "shot") -> Path:
    """Frames of uniform linear grey levels 0.05, 0.10, ... (decodable back within codec error)."""
    for i in range(n):
        write_frame(folder / f"{name}.{i + 1:04d}.exr", np.full((H, W, 4), 0.05 * (i + 1), np.float32), fps=Fraction(24))
    return folder


class Info:
    """What PyAV reports about a movie's video stream (read before the file is closed)."""

    def __init__(self, stream: av.video.stream.VideoStream) -> None:
        cc = stream.codec_context
        self.average_rate = stream.average_rate
        self.codec_name, self.field_order, self.profile, self.pix_fmt = cc.name, cc.field_order, cc.profile, cc.pix_fmt


def decode(path: Path) -> tuple[Info, list[av.VideoFrame]]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        frames = list(container.decode(stream))
        return Info(stream), frames


@pytest.mark.parametrize("order", ["tff", "bff"])
@pytest.mark.parametrize("suffix,codec_name", [(".mov", "prores"), (".mp4", "h264")])
def test_60i_movie_decodes_interlaced(tmp_path: Path, order: str, suffix: str, codec_name: str) -> None:
    res = telecine_sequence(grey_seq(tmp_path / "in", 8), tmp_path / "60i", field_order=order)
    movie = sequence_movie(res.out_dir, tmp_path / f"shot_60i{suffix}")
    stream, frames = decode(movie)
    assert stream.codec_name == codec_name
    assert len(frames) == 10  # 8 film frames -> 20 fields
    assert stream.average_rate == Fraction(30000, 1001)
    assert all(f.interlaced_frame for f in frames)
    assert stream.field_order == (AV_FIELD_TT if order == "tff" else AV_FIELD_BB)
    if codec_name == "prores":
        assert stream.profile == "HQ" and stream.pix_fmt == "yuv422p10le"
    # Video frame 2 is B top / C bottom (tff): its rows alternate between two grey levels.
    luma = frames[2].to_ndarray(format="gray16le").astype(np.float64)
    top, bottom = luma[0::2].mean(), luma[1::2].mean()
    # tff: top rows from B (0.10), bottom from C (0.15); bff the other way round.
    assert (top < bottom) == (order == "tff") and abs(top - bottom) > 2000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["60i", "in", f"shot_60i{suffix}"]  # no temp left


def test_24p_movie_progressive_and_view_transform(tmp_path: Path) -> None:
    movie = sequence_movie(grey_seq(tmp_path / "in", 4), tmp_path / "p.mov", rate=Fraction(24000, 1001), view=ViewTransform(exposure=1.0, ocio_config="none"))
    stream, frames = decode(movie)
    assert len(frames) == 4 and stream.average_rate == Fraction(24000, 1001)
    assert not frames[0].interlaced_frame and stream.field_order == AV_FIELD_PROGRESSIVE
    # Frame 1 is linear 0.10, +1 stop = 0.20 -> sRGB 0.4845; the decoded RGB agrees to 8 bits.
    rgb = frames[1].to_ndarray(format="rgb24").astype(np.float64) / 255
    assert abs(rgb.mean() - float(srgb_encode(np.array(0.20)))) < 2 / 255


def test_view_transform_and_ocio_request() -> None:
    view = ViewTransform(exposure=-1, ocio_config="none")  # the plain sRGB curve (the default is ACES's tone curve)
    out = view(np.array([[[0.0, 0.36, 4.0, 1.0]]], np.float32))
    assert out.dtype == np.uint16 and out[0, 0, 0] == 0 and out[0, 0, 2] == 65535
    assert abs(out[0, 0, 1] / 65535 - float(srgb_encode(np.array(0.18)))) < 1e-4
    # a config that is not there is a clear error naming it (PyOpenColorIO is a dependency)
    with pytest.raises(UsageError, match="studio.ocio"):
        ViewTransform(ocio_config="studio.ocio")


def test_movie_failure_leaves_no_file(tmp_path: Path) -> None:
    seq = grey_seq(tmp_path / "in", 3)
    with pytest.raises(UsageError, match="ProRes goes in a .mov"):
        sequence_movie(seq, tmp_path / "m.mp4", codec="prores")
    (seq / "shot.0003.exr").write_bytes(b"truncated")
    with pytest.raises(Exception, match=r"shot\.0003\.exr"):
        sequence_movie(seq, tmp_path / "m.mov")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_contact_sheet(tmp_path: Path) -> None:
    src = tmp_path / "in"
    for i in range(7):
        rgba = np.zeros((48, 64, 4), np.float32)
        rgba[:24] = 0.18  # top half mid grey, bottom half black: orientation is checked
        rgba[..., 3] = 1
        write_frame(src / f"s.{i:04d}.exr", rgba)
    sheet = contact_sheet(src, tmp_path / "sheet.png", thumb_width=32, columns=4)
    img = matplotlib.image.imread(sheet)
    assert img.shape[0] == 30 + 2 * (24 + 18 + 4) + 4 and img.shape[1] >= 4 * (32 + 4) + 4  # (as wide as its header at least)
    y0, x0 = 30 + 4, 4  # first thumbnail
    default = ViewTransform().encode(np.full((1, 1, 4), 0.18, np.float32))[0, 0, 0]  # the default view (ACES 2.0 SDR)
    assert abs(img[y0 + 2, x0 + 16, 0] - float(default)) < 2 / 255
    assert img[y0 + 20, x0 + 16, 0] == 0
    assert np.allclose(box_resize(np.arange(16.0).reshape(4, 4, 1), 2, 2)[..., 0], [[2.5, 4.5], [10.5, 12.5]])


def test_cli_telecine_inverse_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = grey_seq(tmp_path / "in", 5)
    runner = CliRunner()
    out = runner.invoke(cli, ["telecine", str(src), "-o", str(tmp_path / "60i"), "--pattern", "2:3:3:2",
                              "--field-order", "bff", "--movie", str(tmp_path / "v.mov")], catch_exceptions=False)
    assert out.exit_code == 0, out.output
    assert "wrote 6 frames" in out.output and (tmp_path / "v.mov").is_file()
    assert f"wrote {tmp_path / 'v.mov'} (29.97 fps (30000/1001), interlaced)" in out.output  # the rate it plays at
    assert read_frame(tmp_path / "60i" / "shot.0001.exr").meta["fieldOrder"] == "bff"
    out = runner.invoke(cli, ["telecine", str(tmp_path / "60i"), "-o", str(tmp_path / "back"), "--inverse"],
                        catch_exceptions=False)
    assert out.exit_code == 0 and "wrote 5 frames" in out.output
    for i in range(5):
        np.testing.assert_array_equal(read_frame(tmp_path / "back" / f"shot.{i + 1:04d}.exr").rgba,
                                      read_frame(src / f"shot.{i + 1:04d}.exr").rgba)
    # Errors: one line, exit code 2, nothing written.
    (src / "shot.0003.exr").unlink()
    assert main(["telecine", str(src), "-o", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing frame" in err[0] and "shot.0003.exr" in err[0]
    assert main(["telecine", str(tmp_path / "60i"), "-o", str(tmp_path / "bad"), "--pattern", "2x2"]) == 2
    assert main(["contact-sheet", str(tmp_path / "back"), "-o", str(tmp_path / "c.png")]) == 0
    assert (tmp_path / "c.png").is_file()


def test_deliver_24p_and_60i(tmp_path: Path) -> None:
    assert parse_formats("24p, 60i") == ("24p", "60i")
    with pytest.raises(UsageError, match="unknown format 30p"):
        parse_formats("24p,30p")
    done = deliver(grey_seq(tmp_path / "frames", 4, "cannonball"), tmp_path / "deliver", "24p,60i")
    assert done["24p"] == [tmp_path / "deliver" / "cannonball_24p.mov"]
    assert len(done["60i"]) == 6 and done["60i"][-1].name == "cannonball_60i.mov"
    s24, f24 = decode(done["24p"][0])
    s60, f60 = decode(done["60i"][-1])
    assert (len(f24), s24.average_rate) == (4, Fraction(24000, 1001))
    assert (len(f60), s60.average_rate, f60[0].interlaced_frame) == (5, Fraction(30000, 1001), True)


def test_contact_sheet_accepts_gaps_telecine_refuses_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """After `motion render --frames 0-100x10`: frames 0, 10, ..., 100 (90 numbers missing)."""
    src = tmp_path / "in"
    numbers = list(range(0, 101, 10))
    for k, n in enumerate(numbers):
        write_frame(src / f"shot.{n:04d}.exr", np.full((24, 32, 4), 0.02 * (k + 1), np.float32), fps=Fraction(24))
    seq = discover(src, allow_gaps=True)
    assert seq.numbers == tuple(numbers) and len(seq.missing) == 90 and seq.missing[:3] == (1, 2, 3)
    layout = sheet_layout(seq)
    assert layout.numbers == tuple(numbers) and layout.missing == 90
    assert "frames 0-100 (11 of 101 frames, 90 missing)" in layout.header
    assert sheet_layout(seq, max_frames=4).numbers == (0, 30, 60, 90)  # sampled among existing frames
    assert main(["contact-sheet", str(src), "-o", str(tmp_path / "c.png"), "--width", "32", "--columns", "11"]) == 0
    assert "(11 frames, 90 missing)" in capsys.readouterr().out
    img = matplotlib.image.imread(tmp_path / "c.png")
    shown = [img[30 + 4 + 12, 4 + k * 36 + 16, 0] for k in range(11)]  # each thumbnail's centre, in order
    levels = np.repeat((0.02 * np.arange(1, 12, dtype=np.float32))[:, None, None], 4, axis=2)
    np.testing.assert_allclose(shown, ViewTransform().encode(levels)[:, 0, 0], atol=1 / 255)
    # Telecine and movies stay strict: one line naming the first missing frame, nothing written.
    assert main(["telecine", str(src), "-o", str(tmp_path / "60i")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing frame" in err[0] and "shot.0001.exr" in err[0] and "87 more" in err[0]
    assert not (tmp_path / "60i").exists()
    with pytest.raises(FrameIOError, match=r"missing frame .*shot\.0001\.exr"):
        sequence_movie(src, tmp_path / "m.mov")
    assert not (tmp_path / "m.mov").exists()
