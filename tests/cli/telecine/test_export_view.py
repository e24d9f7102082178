"""`motion export` (EXR -> PNG/JPEG through the movies' view transform) and `motion view`
(the HTML flipbook), on real renders; the flipbook is driven in headless Chromium when it
is installed (apt-get install chromium), and its structure is checked either way."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from farm_util import MOTION, SCENE, TINY, motion
from motion.pipeline.frame_output import read_frame
from motion.pipeline.telecine.export import to_8bit
from motion.pipeline.telecine.movie import ViewTransform


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rendered")
    res = motion("render", SCENE, "-o", out, "--frames", "0-4", "--resolution", "32x24", "--spp", "2", "--no-progress", "--workers", "1")
    assert res.returncode == 0, res.stderr
    return out


def test_export_png_and_jpg_use_the_movies_view_transform(rendered: Path, tmp_path: Path) -> None:
    from PIL import Image

    res = motion("export", rendered, "--format", "png", "--exposure", "1", "-o", tmp_path / "png")
    assert res.returncode == 0, res.stderr
    assert str(tmp_path / "png") in res.stdout
    pngs = sorted((tmp_path / "png").glob("*.png"))
    assert [p.name for p in pngs] == [f"farm-tiny.{f:04d}.png" for f in range(5)]
    view = ViewTransform(exposure=1.0)
    for png in pngs:
        rgba = read_frame(rendered / png.name.replace(".png", ".exr")).rgba
        got = np.asarray(Image.open(png).convert("RGB"))
        assert np.array_equal(got, to_8bit(view(rgba)))
    dark = np.asarray(Image.open(pngs[0]).convert("RGB")).astype(int)
    res = motion("export", rendered, "--format", "jpg")  # default folder: IN_DIR/jpg
    assert res.returncode == 0, res.stderr
    jpgs = sorted((rendered / "jpg").glob("*.jpg"))
    assert len(jpgs) == 5
    jpg = np.asarray(Image.open(jpgs[0]).convert("RGB")).astype(int)
    assert jpg.shape == (24, 32, 3) and jpg.mean() < dark.mean()  # +1 stop is brighter
    assert np.abs(to_8bit(ViewTransform()(read_frame(rendered / "farm-tiny.0000.exr").rgba)).astype(int) - jpg).mean() < 6


def test_export_reports_bad_input_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    res = motion("export", tmp_path / "empty")
    assert res.returncode == 2 and "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.ids: dict[str, dict[str, str | None]] = {}
        self.data: str | None = None
        self._in_data = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if a.get("id"):
            self.ids[a["id"]] = {"tag": tag, **a}  # type: ignore[dict-item]
        self._in_data = a.get("id") == "flipbook-data"

    def handle_data(self, data: str) -> None:
        if self._in_data:
            self.data = (self.data or "") + data

    def handle_endtag(self, tag: str) -> None:
        self._in_data = False


def test_flipbook_page(rendered: Path) -> None:
    res = motion("view", rendered)
    assert res.returncode == 0, res.stderr
    page = rendered / "flipbook" / "index.html"
    assert str(page) in res.stdout
    parsed = _Page()
    parsed.feed(page.read_text())
    assert parsed.ids["scrubber"]["tag"] == "input" and parsed.ids["scrubber"]["type"] == "range"
    assert {"stage", "play", "prev", "next", "info"} <= parsed.ids.keys()
    data = json.loads(parsed.data or "")
    assert [f["frame"] for f in data["frames"]] == list(range(5)) and data["fps"] == 24.0
    assert data["frames"][3]["file"] == "farm-tiny.0003.exr" and data["frames"][3]["spp"] == 2
    assert data["frames"][3]["timecode"] == "00:00:00:03" and data["frames"][3]["time"] == 0.125
    for f in data["frames"]:
        assert (page.parent / f["src"]).is_file()

    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        pytest.skip("no Chromium here (apt-get install chromium): the page's structure was checked, not its script")
    dom = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000", "--dump-dom",
                          page.resolve().as_uri() + "#frame=3"], capture_output=True, text=True, timeout=120).stdout
    shown = _Page()
    shown.feed(dom)
    body = dom[dom.index("<body"): dom.index(">", dom.index("<body"))]
    assert 'data-frame="3"' in body and 'data-loaded="5"' in body and "data-broken" not in body, body
    assert 'id="info-file">farm-tiny.0003.exr<' in dom and 'id="counter">4 / 5<' in dom
    assert shown.ids["stage"]["src"] == data["frames"][3]["src"]


def test_frames_below_0_are_read_by_every_tool(tmp_path: Path) -> None:
    """A timeline from -3: the renderer writes `farm-tiny.-0003.exr`; `export` refused the
    folder ("frames -3..-1 are numbered below 0"), `--deliver` refused before the first
    frame, and the sequence reader of the sheet, telecine and compare did not see those
    files at all. Every tool reads them now, names its outputs as the renderer names
    frames, and prints the range as -3..1 (not -3-1)."""
    import yaml

    from motion.pipeline.telecine.sequence import discover

    doc = yaml.safe_load(SCENE.read_text())
    doc["timeline"].update(first=-3, last=1)
    scene = tmp_path / "neg.yaml"
    scene.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    res = motion("render", scene, "-o", out, *TINY, "--deliver", "contact,24p")
    assert res.returncode == 0, res.stderr
    assert (out / "farm-tiny.-0003.exr").is_file() and (out / "deliver" / "farm-tiny_24p_v001.mov").is_file()
    seq = discover(out)
    assert seq.numbers == (-3, -2, -1, 0, 1) and not seq.missing and seq.padding == 4
    res = motion("export", out, "-o", tmp_path / "png")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == sorted(f"farm-tiny.{n}.png" for n in ("-0003", "-0002", "-0001", "0000", "0001"))
    res = motion("contact-sheet", out, "-o", tmp_path / "sheet.png")
    assert res.returncode == 0 and "(5 frames)" in res.stdout, res.stderr
    res = motion("telecine", out, "-o", tmp_path / "60i")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "60i" / "farm-tiny.-0003.exr").is_file() and len(list((tmp_path / "60i").glob("*.exr"))) == 6
    res = motion("view", out, "-o", tmp_path / "flip" / "index.html")
    assert res.returncode == 0, res.stderr
    res = motion("render", scene, "-o", out, *TINY, "--check")
    assert res.returncode == 0 and "all 5 frames (-3..1) complete" in res.stderr, res.stderr
    plan = motion("render", scene, "-o", out, *TINY, "--dry-run")
    assert "frames:    -3..1 (5)" in plan.stdout, plan.stdout


def test_no_command_allocates_by_the_span_of_frame_numbers(tmp_path: Path) -> None:
    """A folder holding t.0000.exr and t.2147483648.exr: `contact-sheet` and `export`
    grew to 21 GB (the set of the 2**31 numbers absent between them) until the OOM killer
    ended them. Under a 1.5 GiB address-space cap each finishes in seconds; the sheet
    counts the missing numbers, the reader keeps them as one run."""
    import resource
    import sys
    from fractions import Fraction

    from farm_util import MOTION
    from motion.pipeline.frame_output import write_frame

    frames = tmp_path / "frames"
    for n in (0, 2**31):
        write_frame(frames / f"t.{n:04d}.exr", np.full((12, 16, 4), 0.3, np.float32), {"frame": n}, fps=Fraction(24))

    def capped() -> None:  # (every run that reads the folder is capped: the code before took the machine's memory)
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))

    read = ("from motion.pipeline.telecine.sequence import discover\n"
            f"m = discover({str(frames)!r}, allow_gaps=True).missing\n"
            "print(m.runs == ((1, 2**31 - 1),), len(m) == 2**31 - 1, 2**30 in m, m[-1] == 2**31 - 1, m[:2] == (1, 2))")
    said = []
    for argv in ([sys.executable, "-c", read], [MOTION, "contact-sheet", str(frames), "-o", str(tmp_path / "sheet.png")],
                 [MOTION, "export", str(frames), "-o", str(tmp_path / "png")]):
        res = subprocess.run(argv, capture_output=True, text=True, timeout=60, preexec_fn=capped)
        assert res.returncode == 0, res.stderr
        said.append(res.stdout)
    assert said[0].split() == ["True"] * 5
    assert "(2 frames, 2147483647 missing)" in said[1] and (tmp_path / "sheet.png").is_file()
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["t.0000.png", "t.2147483648.png"]


def test_a_range_from_below_0_is_printed_one_way_and_read_back() -> None:
    """A timeline from -10 printed 'frames -10-37' (is that -10 to 37, or -10 and -37?):
    every range that starts below 0 is printed A..B, which --frames reads back as written."""
    from motion.pipeline.farm.selection import parse_frames
    from motion.pipeline.timeline import format_frames, format_range

    assert format_range(-10, 37) == "-10..37" and format_range(-5, -1) == "-5..-1" and format_range(0, 119) == "0-119"
    for frames in (list(range(-10, 38)), list(range(-5, 0)), list(range(-10, 31, 2)), [-3, -1, 4, 5, 6]):
        assert parse_frames(format_frames(frames)) == frames
    assert format_frames(list(range(-10, 38))) == "-10..37" and format_frames(list(range(-10, 31, 2))) == "-10..30x2"


def test_view_open_on_a_headless_machine_says_so(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY).returncode == 0
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "BROWSER")}
    res = subprocess.run([MOTION, "view", str(out), "--open"],
                         capture_output=True, text=True, env={**env, "PATH": "/usr/bin:/bin"}, timeout=120)
    assert res.returncode == 2 and "no web browser can be started here" in res.stderr, res.stderr
    assert (out / "flipbook" / "index.html").is_file()
