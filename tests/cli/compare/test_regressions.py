"""`motion compare` on real renders: a suite of deliberate regressions (material, light,
transform, motion-blur length, a missing object, a texture swap) each fails with the region
that changed named; a seed, a thread count and the variant (llvm vs scalar) pass; frames
made from another scene file (another seed) compare; other settings are compared and
named as notes; golden sets."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from farm_util import ROOT, motion

# A lit wall with four things in a row at the top (a textured poster, a ball, a box) and a
# fast mover at the bottom (24 units/s across the frame: a ~5 px streak at 180 degrees).
# The camera looks down -Z from z = 8: world x, y -> pixel x = 32 + x / U, y = 18 - y / U.
U = 2 * 8 * 0.36397023426620234 / 64  # world units per pixel at z = 0 (fov 40 over 64 px)
SCENE = """
name: regress
timeline: {{fps: 24, first: 0, last: 24}}
camera: {{position: [0, 0, 8], look_at: [0, 0, 0], fov: 40, shutter: {{angle: {shutter}}}}}
lights:
  - {{type: constant, radiance: 0.3}}
  - {{type: point, position: [0, 3, 6], intensity: {light}}}
materials:
  - {{name: wall, type: diffuse, color: 0.5}}
  - {{name: poster, type: diffuse, color: {{file: {texture}}}}}
  - {{name: ball, type: diffuse, color: {ball}}}
  - {{name: box, type: diffuse, color: [0.2, 0.3, 0.8]}}
  - {{name: mover, type: diffuse, color: [0.9, 0.8, 0.1]}}
objects:
  - {{name: wall, shape: rectangle, width: 14, height: 9, material: wall, transform: {{translate: [0, 0, -1]}}}}
  - {{name: poster, shape: rectangle, width: 1.4, height: 1.2, material: poster, transform: {{translate: [-1.8, 0.6, 0]}}}}
  - {{name: ball, shape: sphere, radius: 0.45, material: ball, transform: {{translate: [0, 0.6, 0]}}}}
{box}  - name: mover
    shape: sphere
    radius: 0.3
    material: mover
    motion:
      type: keyframes
      time_unit: seconds
      channels:
        translate:
          keys:
            - {{time: 0.0, value: [-12, -0.9, 0]}}
            - {{time: 1.0, value: [12, -0.9, 0]}}
render: {{resolution: [64, 36], spp: {spp}, max_depth: 3, seed: {seed}}}
"""
BOX = "  - {name: box, shape: cube, size: 0.8, material: box, transform: {translate: [%s, 0.6, 0]}}\n"
BASE = {"shutter": 180, "light": 60, "texture": "grass.jpg", "ball": "[0.8, 0.2, 0.1]", "box": BOX % "1.8", "spp": 32, "seed": 0}
FRAMES = "11-13"


def _pixel_box(x: float, y: float, half_w: float, half_h: float) -> tuple[float, float, float, float]:
    """The pixel box (x0, y0, x1, y1) of a world-space box centred at (x, y) in the z = 0 plane."""
    return 32 + (x - half_w) / U, 18 - (y + half_h) / U, 32 + (x + half_w) / U, 18 - (y - half_h) / U


POSTER = _pixel_box(-1.8, 0.6, 0.7, 0.6)
BALL = _pixel_box(0, 0.6, 0.45, 0.45)
BOX_AT = _pixel_box(1.8, 0.6, 0.4, 0.4)
MOVER = _pixel_box(0, -1.3, 2.0, 0.7)  # frames 11-13: x = -1 .. 1, a streak along x, and its shadow below


def _render(folder: Path, name: str, extra: tuple[str, ...] = (), **changes: object) -> Path:
    scene = folder / f"{name}.yaml"
    if not scene.exists():
        for texture in ("grass.jpg", "stone.jpg"):
            if not (folder / texture).exists():
                shutil.copy(ROOT / "scenes" / "assets" / texture, folder / texture)
        scene.write_text(SCENE.format(**{**BASE, **changes}))
    out = folder / f"out-{name}"
    res = motion("render", scene, "-o", out, "--frames", FRAMES, "--no-progress", "--workers", "1", *extra)
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("regress")


@pytest.fixture(scope="module")
def reference(shots: Path) -> Path:
    return _render(shots, "reference")


def _compare(new: Path, ref: Path, *extra: object) -> tuple[int, str, dict]:
    report = new.parent / f"{new.name}-compare.json"
    res = motion("compare", new, ref, "--json", report, "--allow-different-settings", *extra)
    assert "Traceback" not in res.stderr, res.stderr
    data = json.loads(report.read_text()) if report.exists() else {}
    return res.returncode, res.stdout + res.stderr, data


def _overlaps(region: dict, box: tuple[float, float, float, float]) -> bool:
    x0, y0, x1, y1 = box
    return region["x0"] < x1 and region["x1"] > x0 and region["y0"] < y1 and region["y1"] > y0


REGRESSIONS = {
    # name: (scene changes, the pixel box where the worst region must be, or None for the whole frame)
    "material": ({"ball": "[0.3, 0.2, 0.1]"}, BALL),
    "light": ({"light": 40}, None),
    "transform": ({"box": BOX % "1.55"}, BOX_AT),
    "motion-blur length": ({"shutter": 60}, MOVER),
    "missing object": ({"box": ""}, BOX_AT),
    "texture swap": ({"texture": "stone.jpg"}, POSTER),
}


@pytest.mark.parametrize("name", list(REGRESSIONS))
def test_a_regression_fails_with_its_region_named(shots: Path, reference: Path, name: str) -> None:
    changes, box = REGRESSIONS[name]
    new = _render(shots, name.replace(" ", "-"), **changes)
    code, out, data = _compare(new, reference)
    assert code == 1, out
    assert "FAIL" in out and "different" in out
    assert data["notes"] and "note: frames 11-13: " in out, out  # the change is named, not only seen
    different = [f for f in data["frames"] if f["outcome"] == "different"]
    assert different, out
    for frame in different:
        worst = frame["regions"][0]
        if box is None:
            assert worst["fraction"] > 0.5, (name, worst)  # the whole frame darker
            assert worst["mean_diff"] < 0
        else:
            assert _overlaps(worst, box), (name, worst, box)
    if name == "motion-blur length":
        assert len(different) == 3  # every frame: the streak is shorter in each
    else:
        assert len(different) == 3, out


@pytest.mark.parametrize("name,changes,extra", [
    ("seed", {"seed": 7}, ()),
    ("threads", {}, ("--threads", "1")),
    ("scalar", {}, ("--variant", "scalar_rgb")),
])
def test_noise_only_changes_pass(shots: Path, reference: Path, name: str, changes: dict, extra: tuple[str, ...]) -> None:
    new = _render(shots, name, extra, **changes)
    code, out, data = _compare(new, reference, "-v")
    assert code == 0, out
    assert "PASS" in out
    outcomes = {f["outcome"] for f in data["frames"]}
    assert outcomes <= {"identical", "equal"}, out
    if name == "seed":
        assert outcomes == {"equal"}  # other noise, the same picture
    if name == "scalar":
        assert {f["new_facts"]["variant"] for f in data["frames"]} == {"scalar_rgb"}
        assert data["variants"] == {"scalar_rgb": [11, 12, 13]}


def test_another_scene_file_with_another_seed_is_compared_without_a_note(shots: Path, reference: Path) -> None:
    seed = _render(shots, "seed", (), seed=7)  # its own scene file, seed: 7
    res = motion("compare", seed, reference)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stdout + res.stderr
    assert "3 equal within noise" in res.stdout and "note:" not in res.stderr, res.stdout + res.stderr


def test_same_scene_other_spp_is_compared_and_named_as_a_note(shots: Path) -> None:
    ref = _render(shots, "samescene")
    new = shots / "out-samescene-spp"
    res = motion("render", shots / "samescene.yaml", "-o", new, "--frames", FRAMES, "--no-progress", "--workers", "1", "--spp", "8")
    assert res.returncode == 0, res.stderr
    res = motion("compare", new, ref)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stdout + res.stderr
    assert "note: frames 11-13: render setting spp 8 (new) vs 32 (reference)" in res.stderr, res.stderr
    assert "3 equal within noise" in res.stdout, res.stdout


def test_golden_set_bless_and_compare(shots: Path, reference: Path, tmp_path: Path) -> None:
    golden = tmp_path / "golden"
    res = motion("compare", reference, golden, "--bless")
    assert res.returncode == 0, res.stderr
    manifest = json.loads((golden / "manifest.json").read_text())
    assert [f["frame"] for f in manifest["frames"]] == [11, 12, 13]
    assert manifest["settings"]["spp"] == 32 and manifest["resolution"] == [64, 36] and manifest["scene_digest"]
    assert manifest["motion_version"] and all(f["variant"] for f in manifest["frames"])
    from motion.pipeline.frame_output import read_frame

    kept = read_frame(golden / "regress.0012.exr")
    assert kept.meta["variant"] == manifest["frames"][1]["variant"] and kept.meta["spp"] == 32  # the header kept
    import OpenEXR

    with OpenEXR.File(str(golden / "regress.0012.exr")) as f:
        assert {str(ch.pixels.dtype) for ch in f.channels().values()} == {"float16"}
    # the frames themselves: identical against their own blessing
    res = motion("compare", reference, golden)
    assert res.returncode == 0 and "3 identical" in res.stdout, res.stdout + res.stderr
    # a reference that changed after blessing is bad input, not a verdict
    data = bytearray((golden / "regress.0013.exr").read_bytes())
    data[-1] ^= 0xFF
    (golden / "regress.0013.exr").write_bytes(bytes(data))
    res = motion("compare", reference, golden)
    assert res.returncode == 2 and "not the one blessed" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    # missing new frames fail (exit 1), bad folders are bad input (exit 2)
    res = motion("compare", reference, golden, "--bless")
    partial = tmp_path / "partial"
    partial.mkdir()
    shutil.copy(reference / "regress.0011.exr", partial)
    res = motion("compare", partial, golden)
    assert res.returncode == 1 and "frame 12: missing" in res.stdout, res.stdout + res.stderr
    res = motion("compare", tmp_path / "nowhere", golden)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1


def test_render_with_compare_fails_on_a_regression(shots: Path, reference: Path) -> None:
    _render(shots, "material", **REGRESSIONS["material"][0])  # writes material.yaml (and its frames)
    out = shots / "out-material-compare"
    res = motion("render", shots / "material.yaml", "-o", out, "--frames", FRAMES, "--no-progress", "--workers", "1",
                 "--compare", reference, "--allow-different-settings")
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    assert "FAIL: 3 frames" in res.stderr and res.stderr.strip().splitlines()[-1].startswith("error: 3 of 3 frames differ")
    assert (out / "compare" / "index.html").is_file() and (out / "compare" / "junit.xml").is_file()
    assert len(list(out.glob("regress.*.exr"))) == 3  # the frames are written whatever the verdict
