"""The timecode a shot's frames and deliverables carry: drop-frame at 29.97 and 59.94, from
the frame number at the scene's rate, and the same wherever it is shown (EXR, movies,
flipbook, contact sheet, report)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import av
import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import frames_in, motion
from farm_util import report


@pytest.mark.parametrize("fps, frame, code", [("29.97", 1800, "00:01:00;02"), ("59.94", 3600, "00:01:00;04"), ("29.97", 17982, "00:10:00;00")])
def test_frames_at_29_97_and_59_94_carry_drop_frame_timecode(tmp_path: Path, fps: str, frame: int, code: str) -> None:
    from motion.pipeline.frame_output import header_timecode, read_header

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("fps: 24, first: 0, last: 1", f"fps: {fps}, first: {frame}, last: {frame}"))
    res = motion("render", scene, "-o", tmp_path / "out")
    assert res.returncode == 0, res.stderr
    (path,) = frames_in(tmp_path / "out")
    assert header_timecode(read_header(path)) == code  # before: non-drop at 2997/100


@pytest.fixture(scope="module")
def shot_1001(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess]:
    """A shot numbered 1001-1006 at 24 fps rendered with 24p, 60i and a contact sheet."""
    folder = tmp_path_factory.mktemp("tc")
    scene = folder / "tc.yaml"
    scene.write_text("timeline: {fps: 24, first: 1001, last: 1006}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
                     "lights: [{type: constant, radiance: 1}]\nobjects: [{name: b, shape: sphere, radius: 0.5}]\nrender: {resolution: [16, 12], spp: 1}\n")
    res = motion("render", scene, "-o", folder / "out", "--deliver", "24p,60i,contact", "--no-progress")
    assert res.returncode == 0, res.stderr
    return folder / "out", res


def test_timecode_comes_from_the_frame_number_and_the_rate_is_named(shot_1001: tuple[Path, subprocess.CompletedProcess]) -> None:
    """A shot numbered 1001-1006 at 24 fps: frame 1001's timecode is 00:00:41:17 in its EXR
    and its 24p movie (it was 00:00:00:00); the 24p movie plays at 23.976 and says so."""
    from motion.pipeline.frame_output import read_header, timecode_str

    out, res = shot_1001
    assert timecode_str(read_header(out / "tc.1001.exr")["timeCode"]) == "00:00:41:17"
    with av.open(str(out / "deliver" / "tc_24p_v001.mov")) as c:
        assert c.streams.video[0].metadata.get("timecode") == "00:00:41:17"
    assert "tc_24p_v001.mov (23.976 fps (24000/1001))" in res.stderr
    assert "tc_60i_v001.mov (29.97 fps (30000/1001) interlaced, 2 fields a frame)" in res.stderr
    made = json.loads((out / "deliver" / "manifest.json").read_text())["deliverables"]
    assert made["24p"]["versions"]["v001"]["outputs"][0]["rate"] == "23.976 fps (24000/1001)"


def test_movies_flipbook_sheet_and_report_name_the_rate_and_the_frames_timecode(shot_1001: tuple[Path, subprocess.CompletedProcess]) -> None:
    """Wherever else the rate or the timecode is shown it agrees with the frames and the
    movies: the flipbook of frames 1001.. says 00:00:41:17 (it counted from the folder's
    first frame: 00:00:00:00) and of their 60i pulldown 00:00:41:21, as that movie's
    timecode does; the flipbook and the contact sheet name 29.97 fps (30000/1001) (they
    said '30000/1001 fps'); each movie's comment names its rate, scan and view; the report
    gives each movie's rate as the manifest does."""
    from motion.pipeline.telecine.contact_sheet import sheet_layout
    from motion.pipeline.telecine.sequence import discover

    out, _ = shot_1001
    interlaced = out / "deliver" / "60i_v001"
    with av.open(str(out / "deliver" / "tc_60i_v001.mov")) as c:
        assert c.streams.video[0].metadata.get("timecode") == "00:00:41:21"
        assert c.metadata.get("comment", "").startswith("29.97 fps (30000/1001), interlaced tff; view: OCIO")
    with av.open(str(out / "deliver" / "tc_24p_v001.mov")) as c:
        assert c.metadata.get("comment", "").startswith("23.976 fps (24000/1001), progressive; view: OCIO")
    for folder, first, rate in ((out, "00:00:41:17", "24 fps"), (interlaced, "00:00:41:21", "29.97 fps (30000/1001)")):
        res = motion("view", folder)
        assert res.returncode == 0, res.stderr
        page = (folder / "flipbook" / "index.html").read_text()
        data = json.loads(page.split('id="flipbook-data" type="application/json">', 1)[1].split("</script>", 1)[0])
        assert data["frames"][0]["frame"] == 1001 and data["frames"][0]["timecode"] == first
        assert data["fps_text"] == rate
    assert sheet_layout(discover(interlaced)).header.endswith("  29.97 fps (30000/1001)")
    rates = report(out)["deliverables"]["rates"]
    assert rates == {str(out / "deliver" / "tc_24p_v001.mov"): "23.976 fps (24000/1001)",
                     str(out / "deliver" / "tc_60i_v001.mov"): "29.97 fps (30000/1001) interlaced, 2 fields a frame"}
