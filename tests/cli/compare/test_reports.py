"""The reports of `motion compare`: JUnit XML that validates against Jenkins' junit-10.xsd
(what pytest, GitHub Actions, GitLab and Jenkins read), and the HTML report driven in
headless Chromium (hover/click flips between reference and new; its images load; regions
are marked), on real EXR files written by frame_output: a picture with independent noise
per frame, one frame with a brighter patch, frames from two variants."""

from __future__ import annotations

import json
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from farm_util import ROOT, motion
from motion.pipeline.frame_output import write_frame

XSD = ROOT / "tests" / "data" / "junit-10.xsd"
W, H = 96, 54
PATCH = (60, 12, 84, 30)  # x0, y0, x1, y1 of the changed patch in frame 2


def _picture() -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W] / float(H)
    pic = np.stack([0.2 + 0.3 * xx, 0.3 + 0.4 * yy, 0.5 + 0.2 * np.sin(6 * xx), np.ones_like(xx)], axis=2)
    pic[20:40, 10:30, :3] = [0.8, 0.6, 0.2]
    return pic


def _write(folder: Path, frame: int, seed: int, variant: str, patch: bool = False) -> None:
    rng = np.random.default_rng(seed)
    pic = _picture()
    if patch:
        x0, y0, x1, y1 = PATCH
        pic[y0:y1, x0:x1, 1] *= 1.3
    noisy = pic * (1.0 + 0.1 * rng.standard_normal(pic.shape))
    noisy[..., 3] = 1.0
    meta = {"frame": frame, "variant": variant, "seed": seed, "spp": 16, "scene_hash": "abc", "renderer": "motion-render-1",
            "render_settings": json.dumps({"spp": 16, "filter": "box", "resolution": [W, H], "seed": seed, "variant": variant})}
    write_frame(folder / f"shot.{frame:04d}.exr", noisy, meta, pixel_type="half")


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    root = tmp_path_factory.mktemp("reports")
    for frame in range(4):
        _write(root / "ref", frame, 100 + frame, "llvm_ad_rgb")
        _write(root / "new", frame, 200 + frame, "cuda_ad_rgb" if frame == 0 else "llvm_ad_rgb", patch=frame == 2)
    res = motion("compare", root / "new", root / "ref", "--report", root / "report")
    return root, res


def test_exit_code_summary_and_json(compared: tuple[Path, object]) -> None:
    root, res = compared
    assert res.returncode == 1, res.stderr  # type: ignore[attr-defined]
    lines = res.stdout.strip().splitlines()  # type: ignore[attr-defined]
    assert any(line.startswith("FAIL: 4 frames") and "3 equal within noise, 1 different" in line for line in lines), lines
    assert len(res.stderr.strip().splitlines()) == 1 and "1 of 4 frames differ" in res.stderr  # type: ignore[attr-defined]
    data = json.loads((root / "report" / "compare.json").read_text())
    assert [f["outcome"] for f in data["frames"]] == ["equal", "equal", "different", "equal"]
    worst = data["frames"][2]["regions"][0]
    x0, y0, x1, y1 = PATCH
    assert worst["x0"] < x1 and worst["x1"] > x0 and worst["y0"] < y1 and worst["y1"] > y0 and worst["channel"] == "G" and worst["mean_diff"] > 0
    assert data["frames"][2]["flip"] > 0  # the perceptual score beside the numeric one
    assert data["variants"] == {"cuda_ad_rgb": [0], "llvm_ad_rgb": [1, 2, 3]}


def test_junit_validates_against_the_schema_ci_systems_use(compared: tuple[Path, object]) -> None:
    import xmlschema

    root, _ = compared
    junit = root / "report" / "junit.xml"
    xmlschema.XMLSchema(str(XSD)).validate(str(junit))  # raises on any violation
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("tests") == "4" and suite.get("failures") == "1"
    cases = suite.findall("testcase")
    assert [c.get("name") for c in cases] == [f"frame {n:04d}" for n in range(4)]
    failure = cases[2].find("failure")
    assert failure is not None and failure.get("type") == "different" and "G" in (failure.get("message") or "")
    assert "variant llvm_ad_rgb" in (failure.text or "")
    assert all(c.find("failure") is None for i, c in enumerate(cases) if i != 2)


def test_an_invalid_junit_file_is_caught_by_the_check(tmp_path: Path) -> None:
    """The schema check can fail: a test case without its required name."""
    import xmlschema

    bad = tmp_path / "bad.xml"
    bad.write_text('<testsuites><testsuite name="x" tests="1" failures="0" errors="0"><testcase classname="c"/></testsuite></testsuites>')
    with pytest.raises(xmlschema.XMLSchemaValidationError):
        xmlschema.XMLSchema(str(XSD)).validate(str(bad))


def test_html_report_in_headless_chromium(compared: tuple[Path, object]) -> None:
    root, _ = compared
    page = root / "report" / "index.html"
    text = page.read_text()
    assert 'id="frame-2"' in text and 'id="frame-1"' not in text  # a section for the frame that differs
    for kind in ("ref", "new", "diff", "flip", "z"):
        assert (root / "report" / "img" / f"000002-{kind}.png").is_file()
    assert "cuda_ad_rgb: 1 frame(s) (0)" in text and "llvm_ad_rgb: 3 frame(s) (1-3)" in text
    assert text.count('class="region"') >= 4  # the worst region marked on each map
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        pytest.skip("no Chromium here (apt-get install chromium): the page's structure was checked, not its script")

    def dom(fragment: str) -> str:
        return subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000", "--dump-dom",
                               page.resolve().as_uri() + fragment], capture_output=True, text=True, timeout=120).stdout

    shown = dom("#frame=2&show=ref")
    body = shown[shown.index("<body"): shown.index(">", shown.index("<body"))]
    images = text.count("<img ")
    assert f'data-loaded="{images}"' in body and "data-broken" not in body and 'data-frame="2"' in body, body
    assert 'class="pane swap showing-ref" data-showing="ref"' in shown and 'class="which">reference<' in shown
    plain = dom("#frame=2")
    assert 'class="pane swap" data-showing="new"' in plain and 'class="which">new<' in plain


def test_denoised_frames_are_tested_on_their_noisy_layer(tmp_path: Path) -> None:
    """A denoised frame keeps its noisy beauty as the `noisy` layer: that is what the test
    reads (the denoised beauties here are the same picture; their noisy layers differ by
    noise in one pair and by a brighter patch in the other)."""
    from motion.pipeline.compare import compare_sequences

    rng = np.random.default_rng(3)
    pic = _picture()
    for side, frame, patch in (("ref", 0, False), ("ref", 1, False), ("new", 0, False), ("new", 1, True)):
        noisy = pic.copy()
        if patch:
            x0, y0, x1, y1 = PATCH
            noisy[y0:y1, x0:x1, 1] *= 1.3
        noisy = noisy * (1.0 + 0.1 * rng.standard_normal(pic.shape))
        noisy[..., 3] = 1.0
        meta = {"frame": frame, "variant": "llvm_ad_rgb", "seed": frame, "spp": 16, "scene_hash": "abc", "renderer": "motion-render-1",
                "render_settings": json.dumps({"spp": 16, "filter": "box", "denoise": "oidn"})}
        write_frame(tmp_path / side / f"shot.{frame:04d}.exr", pic, meta, aovs={"noisy": noisy, "albedo": pic[..., :3]}, pixel_type="half")
    result = compare_sequences(tmp_path / "new", tmp_path / "ref", workers=1)
    assert [(f.layer, f.outcome) for f in result.frames] == [("noisy", "equal"), ("noisy", "different")]


def test_notes_name_their_frames_as_the_frames_grammar_reads_them() -> None:
    """A note's frames are printed by the timeline's one range printer: frames below 0 as
    'A..B' (read back as written by --frames), not '-5--3'."""
    from motion.pipeline.compare.comparison import gather_notes
    from motion.pipeline.farm.selection import parse_frames

    lines = gather_notes({-5: ["spp differs"], -4: ["spp differs"], -3: ["spp differs"], 7: ["spp differs"]})
    assert lines == ["frames -5..-3,7: spp differs"]
    assert parse_frames(lines[0].split(" ")[1][:-1]) == [-5, -4, -3, 7]
