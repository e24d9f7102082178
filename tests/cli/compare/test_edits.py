"""Golden frames stand for the expected picture, not for the scene file's bytes: in a fresh
output folder, a comment, a rename and another seed (`--seed`) compare equal (exit 0); a
changed material is compared and named as a note in the console, the HTML and the JUnit
report (exit 1 when its pixels differ, 0 when they are equal within noise); a resize
cannot be compared (exit 2, before any frame renders). `render --compare` checks its
references and OUTPUT/compare before the work. Real renders: 32x18, 8 spp, 3 frames."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from farm_util import ROOT, motion

SCENE = """name: edit
timeline: {fps: 24, first: 0, last: 2}
camera: {position: [0, 0, 8], look_at: [0, 0, 0], fov: 40}
lights:
  - {type: constant, radiance: 0.3}
  - {type: point, position: [0, 3, 6], intensity: 60}
materials:
  - {name: wall, type: diffuse, color: WALL}
  - {name: BALL, type: diffuse, color: [0.8, 0.2, 0.1]}
objects:
  - {name: wall, shape: rectangle, width: 14, height: 9, material: wall, transform: {translate: [0, 0, -1]}}
  - name: BALL
    shape: sphere
    radius: 0.6
    material: BALL
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate:
          keys:
            - {time: 0.0, value: [-1, 0, 0]}
            - {time: 1.0, value: [1, 0, 0]}
render: {resolution: [32, 18], spp: 8, max_depth: 3, seed: 0}
"""
NOTE = "note: frames 0-2: material wall (m0) differs"  # render --compare names it from the scene
COUNTED = "note: frames 0-2: material 1 of the scene (m0) differs"  # motion compare counts it (the frames' scene may have changed since)


def _scene(folder: Path, name: str, wall: str = "0.5", ball: str = "ball", comment: str = "") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(SCENE.replace("WALL", wall).replace("BALL", ball) + comment)
    return path


def _render(scene: Path, out: Path, *extra: object) -> tuple[int, str]:
    res = motion("render", scene, "-o", out, "--no-progress", "--workers", "1", *extra)
    assert "Traceback" not in res.stderr, res.stderr
    return res.returncode, res.stdout + res.stderr


@pytest.fixture(scope="module")
def golden(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("edits")
    code, out = _render(_scene(root, "shot"), root / "base")
    assert code == 0, out
    res = motion("compare", root / "base", root / "golden", "--bless")
    assert res.returncode == 0, res.stderr
    return root / "golden"


def test_a_comment_a_rename_and_another_seed_compare_equal(golden: Path, tmp_path: Path) -> None:
    scene = _scene(tmp_path, "edited", ball="red", comment="# a comment\n")
    code, out = _render(scene, tmp_path / "fresh", "--seed", "7", "--compare", golden)
    assert code == 0, out
    assert "PASS: 3 frames" in out and "3 equal within noise" in out and "note:" not in out, out
    data = json.loads((tmp_path / "fresh" / "compare" / "compare.json").read_text())
    assert all(f["new_facts"]["seed"] != f["ref_facts"]["seed"] for f in data["frames"])  # --seed took effect
    assert data["notes"] == []
    suite = ET.parse(tmp_path / "fresh" / "compare" / "junit.xml").getroot()
    assert suite.attrib["tests"] == "3" and suite.attrib["failures"] == "0"


def test_a_changed_material_is_compared_and_named(golden: Path, tmp_path: Path) -> None:
    scene = _scene(tmp_path, "brighter", wall="0.515")  # the wall 3% brighter, the same seed
    out_dir = tmp_path / "fresh"
    code, out = _render(scene, out_dir, "--compare", golden, "--allow-different-settings")
    assert code == 1, out
    assert NOTE in out and "FAIL: 3 frames" in out and "3 different" in out, out
    import xmlschema

    xmlschema.XMLSchema(str(ROOT / "tests" / "data" / "junit-10.xsd")).validate(str(out_dir / "compare" / "junit.xml"))  # notes and all
    junit = ET.parse(out_dir / "compare" / "junit.xml").getroot()
    cases = junit.findall(".//testcase")
    assert [c.attrib["name"] for c in cases] == ["frame 0000", "frame 0001", "frame 0002"]
    assert all(c.find("failure") is not None and "note: material wall (m0) differs" in c.find("failure").text for c in cases)
    assert any(p.attrib["name"] == "note" and "material wall" in p.attrib["value"] for p in junit.iter("property"))
    page = (out_dir / "compare" / "index.html").read_text()
    assert '<ul id="allowed"><li>frames 0-2: material wall (m0) differs</li></ul>' in page
    res = motion("compare", out_dir, golden)  # the same verdict and note from motion compare
    assert res.returncode == 1 and COUNTED in res.stderr, res.stdout + res.stderr


def test_a_changed_material_equal_within_noise_passes_with_its_note(golden: Path, tmp_path: Path) -> None:
    scene = _scene(tmp_path, "tiny", wall="0.5001")
    code, out = _render(scene, tmp_path / "fresh", "--seed", "3", "--compare", golden)
    assert code == 0, out
    assert NOTE in out and "PASS: 3 frames" in out, out


def test_a_resize_cannot_be_compared(golden: Path, tmp_path: Path) -> None:
    scene = _scene(tmp_path, "shot")
    code, out = _render(scene, tmp_path / "resized", "--resolution", "48x27", "--compare", golden)
    assert code == 2 and len(out.strip().splitlines()) == 1, out
    assert "48x27" in out and "32x18" in out and "cannot be compared" in out
    assert not list((tmp_path / "resized").glob("*.exr"))  # refused before any frame
    code, out = _render(scene, tmp_path / "resized", "--resolution", "48x27")
    assert code == 0, out
    res = motion("compare", tmp_path / "resized", golden)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "cannot be compared" in res.stderr, res.stderr


def test_render_compare_checks_before_any_frame(golden: Path, tmp_path: Path) -> None:
    scene = _scene(tmp_path, "shot")
    code, out = _render(scene, tmp_path / "a", "--compare", tmp_path / "nowhere")
    assert code == 2 and len(out.strip().splitlines()) == 1 and "nowhere" in out, out
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "compare").write_text("a file where the reports go")
    code, out = _render(scene, tmp_path / "b", "--compare", golden)
    assert code == 2 and len(out.strip().splitlines()) == 1 and "compare" in out, out
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "manifest.json").write_text('{"format": "motion-golden/1", "frames": [{"frame": 1e400}]}')
    code, out = _render(scene, tmp_path / "c", "--compare", damaged)
    assert code == 2 and len(out.strip().splitlines()) == 1 and "frames[0].frame" in out, out
    for folder in ("a", "b", "c"):
        assert not list((tmp_path / folder).glob("*.exr"))
