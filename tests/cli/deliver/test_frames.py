"""Which frames a deliverable is made of: the frames the run selected (rebuilt when they
change), what a preset's spread allows, frames below 0."""

from __future__ import annotations

import json
from pathlib import Path

import av
import yaml

from _scenes import TWO_FRAMES as BASE
from farm_util import motion
from farm_util import SCENE, TINY, report


def test_deliver_over_negative_frames_is_made(tmp_path: Path) -> None:
    """Frames below 0 are read by every tool (docs/telecine.md): the deliverable of a
    timeline from -2 is made of its four frames (it was refused before the first frame)."""
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("first: 0, last: 1", "first: -2, last: 1"))
    res = motion("render", scene, "-o", tmp_path / "out", "--deliver", "contact")
    assert res.returncode == 0, res.stderr
    made = json.loads((tmp_path / "out" / "deliver" / "manifest.json").read_text())["deliverables"]["contact"]["versions"]["v001"]
    assert made["frames"] == "-2..1" and sorted(map(int, made["frame_files"])) == [-2, -1, 0, 1]


def _movie_frames(path: Path) -> int:
    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0))


def test_a_deliverable_is_made_from_the_selected_frames_and_rebuilt_when_they_change(tmp_path: Path) -> None:
    """`--frames 2-5 --deliver 24p --deliver-frames 2-5` in a folder of frames 0-7: the movie
    holds the 4 frames asked for (it held all 8 before); re-rendering them makes a new version."""
    out = tmp_path / "out"
    assert motion("render", SCENE, "-o", out, "--frames", "0-7", *TINY).returncode == 0
    res = motion("render", SCENE, "-o", out, "--frames", "2-5", *TINY, "--deliver", "24p", "--deliver-frames", "2-5")
    assert res.returncode == 0, res.stderr
    movie = out / "deliver" / "farm-tiny_24p_2-5_v001.mov"
    assert _movie_frames(movie) == 4
    assert json.loads((out / "deliver" / "manifest.json").read_text())["deliverables"]["24p@2-5"]["versions"]["v001"]["frames"] == "2-5"
    res = motion("render", SCENE, "-o", out, "--frames", "2-5", "--resolution", "16x12", "--spp", "2", "--no-progress", "--deliver", "24p", "--deliver-frames", "2-5")
    assert res.returncode == 0, res.stderr
    assert "frames 2-5 exist but were made with other settings (spp 1 -> 2): they will be replaced" in res.stderr
    assert report(out)["deliverables"]["status"] == {"24p": "made"}


def test_a_preset_spread_makes_what_it_can_of_the_scenes_deliverables(tmp_path: Path) -> None:
    """The scene asks for 24p, 60i and a contact sheet (output.deliver); the ci-smoke
    preset spreads 3 frames over the shot: the run exits 0, makes the contact sheet and
    says why the movies are left out (exit 2 before: '--deliver needs a gapless run')."""
    doc = yaml.safe_load(SCENE.read_text())
    doc.setdefault("output", {})["deliver"] = ["24p", "60i", "contact"]
    scene = tmp_path / "farm-tiny.yaml"
    scene.write_text(yaml.safe_dump(doc))
    res = motion("render", scene, "-o", tmp_path / "out", "--preset", "ci-smoke", "--no-progress")
    assert res.returncode == 0, res.stderr
    assert "24p: not made: the shot (frames 0-47) lacks frames 1-23,25-46" in res.stderr
    assert (tmp_path / "out" / "deliver" / "farm-tiny_contact_v001.png").is_file()
    assert not list((tmp_path / "out" / "deliver").glob("farm-tiny_24p*"))
    part = motion("render", scene, "-o", tmp_path / "full", "--frames", "0-3", "--deliver-frames", "0-3", *TINY)
    assert part.returncode == 0 and (tmp_path / "full" / "deliver" / "farm-tiny_24p_0-3_v001.mov").is_file(), part.stderr
