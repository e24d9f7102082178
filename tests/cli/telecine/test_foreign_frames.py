"""`motion telecine` and `motion contact-sheet` of a shot's output folder that also holds
frames outside the scene's timeline (a render from before `first: 1001`): the timeline's
frames only, the foreign ones named (issue 38, item 4); before, the two runs were one
sequence with a gap (exit 2) or one sheet of both."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from farm_util import TINY, motion
from tests.cli.shot.test_reruns import SHOT


def _shot_with_foreign_frames(tmp_path: Path) -> tuple[Path, Path]:
    """A folder with frames 0-7 of the scene before its timeline moved and 1001-1008 after."""
    scene, out = tmp_path / "keys.yaml", tmp_path / "out"
    scene.write_text(yaml.safe_dump(SHOT, sort_keys=False))
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    doc = json.loads(json.dumps(SHOT))
    doc["timeline"].update(first=1001, last=1008)
    scene.write_text(yaml.safe_dump(doc, sort_keys=False))
    run = motion("render", scene, "-o", out, *TINY)
    assert run.returncode == 0, run.stderr
    assert len(list(out.glob("keys.*.exr"))) == 16
    return scene, out


def test_telecine_of_a_shot_folder_takes_the_timeline_frames_and_names_the_foreign(tmp_path: Path) -> None:
    """8 film frames of 1001-1008 -> 10 video frames of 3:2, numbered from 1001, their
    field sources inside 1001-1008; frames 0-7 named as foreign, and none of them used."""
    from motion.pipeline.frame_output import read_meta

    _, out = _shot_with_foreign_frames(tmp_path)
    res = motion("telecine", out, "-o", tmp_path / "60i")
    assert res.returncode == 0, res.stderr
    assert "frames 0-7 lie outside the timeline 1001-1008" in res.stderr and "foreign, left out" in res.stderr
    made = sorted((tmp_path / "60i").glob("keys.*.exr"))
    assert len(made) == 10 and made[0].name == "keys.1001.exr"
    sources = {int(read_meta(p)[k]) for p in made for k in ("topFieldSource", "bottomFieldSource")}
    assert sources == set(range(1001, 1009))


def test_contact_sheet_of_a_shot_folder_shows_the_timeline_frames(tmp_path: Path) -> None:
    """The sheet holds the 8 frames of the timeline, not 16 frames and 993 missing."""
    _, out = _shot_with_foreign_frames(tmp_path)
    res = motion("contact-sheet", out, "-o", tmp_path / "sheet.png")
    assert res.returncode == 0, res.stderr
    assert "(8 frames)" in res.stdout and "foreign" in res.stderr


def test_a_folder_without_a_shot_record_is_read_as_before(tmp_path: Path) -> None:
    """Frames copied to a folder of their own (no shot record): the folder's one sequence."""
    _, out = _shot_with_foreign_frames(tmp_path)
    plain = tmp_path / "plain"
    plain.mkdir()
    for p in sorted(out.glob("keys.100*.exr")):
        (plain / p.name).write_bytes(p.read_bytes())
    res = motion("telecine", plain, "-o", tmp_path / "60i")
    assert res.returncode == 0, res.stderr
    assert "foreign" not in res.stderr and len(list((tmp_path / "60i").glob("keys.*.exr"))) == 10
