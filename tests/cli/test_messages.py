"""Messages for a user's slips, each located, with did-you-mean where a near name exists:
a misspelt preset, a preset file that is not there, a scheduler address whose '://' is
written wrong, a missing asset beside a near-named one, a file named .obj that is not one."""

from __future__ import annotations

from pathlib import Path

import pytest

from _support import SCENES, run_motion

SCENE = """timeline: {fps: 24, first: 0, last: 1}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
materials: [{name: m, type: diffuse, color: {file: tex/crates.png}}]
objects:
  - {name: a, shape: mesh, file: prop.obj, material: m}
"""
OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _last(proc) -> str:
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    return proc.stderr.strip().splitlines()[-1]


def test_a_misspelt_preset_gets_did_you_mean(tmp_path: Path) -> None:
    line = _last(run_motion("render", str(SCENES / "bouncing-balls.yaml"), "--preset", "preveiw", "-o", str(tmp_path / "o"), "--dry-run"))
    assert "unknown preset 'preveiw'; did you mean 'preview'?" in line, line


def test_a_preset_file_that_is_not_there_is_file_not_found(tmp_path: Path) -> None:
    (tmp_path / "nightly.yaml").write_text("frame_count: 2\n")
    line = _last(run_motion("render", str(SCENES / "bouncing-balls.yaml"), "--preset", "./nope.yaml", "-o", str(tmp_path / "o"), "--dry-run", cwd=tmp_path))
    assert "--preset ./nope.yaml: file not found" in line and "unknown preset" not in line, line
    line = _last(run_motion("render", str(SCENES / "bouncing-balls.yaml"), "--preset", "nightley.yaml", "-o", str(tmp_path / "o"), "--dry-run", cwd=tmp_path))
    assert "--preset nightley.yaml: file not found; did you mean 'nightly.yaml'?" in line, line


@pytest.mark.parametrize("address", ["tcp//127.0.0.1:8786", "tcp:/127.0.0.1:8786", "tpc//127.0.0.1:8786"])
def test_a_malformed_scheme_is_named_with_the_address_meant(address: str) -> None:
    from motion.pipeline.errors import UsageError
    from motion.pipeline.farm.address import parse_address

    with pytest.raises(UsageError) as err:
        parse_address(address)
    assert "the scheme is malformed" in str(err.value) and "did you mean 'tcp://127.0.0.1:8786'?" in str(err.value)
    assert "no port" not in str(err.value)
    assert parse_address("127.0.0.1:8786") == parse_address("tcp://127.0.0.1:8786") == ("tcp", "127.0.0.1", 8786)


def test_a_malformed_scheduler_address_on_the_command_line(tmp_path: Path) -> None:
    line = _last(run_motion("render", str(SCENES / "bouncing-balls.yaml"), "--scheduler", "tcp//127.0.0.1:8786", "-o", str(tmp_path / "o"), "--dry-run"))
    assert "--scheduler 'tcp//127.0.0.1:8786': the scheme is malformed" in line and "did you mean 'tcp://127.0.0.1:8786'?" in line, line


def test_a_missing_asset_names_the_near_file_in_its_folder(tmp_path: Path) -> None:
    from PIL import Image

    (tmp_path / "tex").mkdir()
    Image.new("RGB", (4, 4)).save(tmp_path / "tex" / "crate.png")
    (tmp_path / "prop.obj").write_text(OBJ)
    (tmp_path / "s.yaml").write_text(SCENE)
    proc = run_motion("validate", str(tmp_path / "s.yaml"))
    assert proc.returncode == 2, proc.stderr
    assert "s.yaml:3" in proc.stderr and "materials[0].color.file" in proc.stderr
    assert "file not found: tex/crates.png" in proc.stderr and "did you mean 'tex/crate.png'?" in proc.stderr, proc.stderr


@pytest.mark.parametrize("content", ["text", "png"])
def test_a_file_named_obj_that_is_not_one_says_so(tmp_path: Path, content: str) -> None:
    """A text file or a PNG named prop.obj: "not an OBJ mesh (it starts with ...)", located
    at the object's file, not "the mesh has no vertices"."""
    from PIL import Image

    (tmp_path / "tex").mkdir()
    Image.new("RGB", (4, 4)).save(tmp_path / "tex" / "crates.png")
    if content == "png":
        Image.new("RGB", (4, 4)).save(tmp_path / "prop.obj", format="PNG")
    else:
        (tmp_path / "prop.obj").write_text("These are the notes for the prop,\nnot its mesh.\n")
    (tmp_path / "s.yaml").write_text(SCENE)
    proc = run_motion("validate", str(tmp_path / "s.yaml"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "objects[0].file" in proc.stderr and "not an OBJ mesh (it starts with" in proc.stderr, proc.stderr
    assert ("a PNG image" if content == "png" else "'These are the notes for the prop,'") in proc.stderr, proc.stderr
    assert "no vertices" not in proc.stderr
