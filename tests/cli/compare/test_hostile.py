"""`motion compare` against hostile input: its verdict cannot be fooled and its reports
stay valid. A non-finite pixel is a difference; an all-black reference gets a verdict;
only the files a golden manifest lists (inside the set, with their digest) are
references; nothing allocates by the span of frame numbers; `--bless --frames` blesses
those frames and never into NEW itself; report paths are checked before the work; Ctrl-C
or SIGTERM stops a pool of workers at once. Small real EXR frames, the real CLI."""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from farm_util import MOTION, ROOT, as_from_a_terminal, motion
from motion.pipeline.frame_output import write_frame

W, H = 32, 18


def _picture(seed: int, w: int = W, h: int = H) -> np.ndarray:
    """A smooth picture with 5% independent noise per pixel (another seed, other noise)."""
    yy, xx = np.mgrid[0:h, 0:w] / float(h)
    pic = np.stack([0.2 + 0.3 * xx, 0.3 + 0.4 * yy, 0.5 + 0.2 * np.sin(6 * xx), np.ones_like(xx)], axis=2)
    noisy = pic * (1.0 + 0.05 * np.random.default_rng(seed).standard_normal(pic.shape))
    noisy[..., 3] = 1.0
    return noisy.astype(np.float32)


def _write(folder: Path, frame: int, pixels: np.ndarray, seed: int = 0) -> Path:
    meta = {"variant": "llvm_ad_rgb", "seed": seed, "spp": 16, "scene_hash": "abc", "renderer": "motion-render-1",
            "render_settings": json.dumps({"spp": 16, "filter": "box", "seed": seed})}
    return write_frame(folder / f"t.{frame:04d}.exr", pixels, meta, pixel_type="float")


def _no_nan_tokens(text: str) -> dict:
    def refuse(token: str) -> None:
        raise AssertionError(f"compare.json holds {token}, which is not JSON")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("value", [np.inf, np.nan])
@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_non_finite_pixel_is_a_difference_and_reports_stay_valid(tmp_path: Path, value: float, workers: str) -> None:
    ref, new = tmp_path / "ref", tmp_path / "new"
    for frame in range(8):  # 8 frames: the pool with 2 workers
        pic = _picture(frame)
        _write(ref, frame, pic)
        bad = pic.copy()
        if frame == 3:
            bad[5, 7, :] = value  # every channel of one pixel (the exact path of an otherwise identical frame)
        _write(new, frame, bad)
    res = motion("compare", new, ref, "--report", tmp_path / "report", "--workers", workers, "--flip", "all")
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stdout + res.stderr
    assert "frame 3: different at x 7-7, y 5-5" in res.stdout and "NaN or infinite" in res.stdout, res.stdout
    data = _no_nan_tokens((tmp_path / "report" / "compare.json").read_text())
    assert [f["outcome"] for f in data["frames"]] == ["identical"] * 3 + ["different"] + ["identical"] * 4
    assert data["frames"][3]["regions"][0]["nonfinite"] == 1 and data["frames"][3]["regions"][0]["z"] is None
    import xmlschema

    xmlschema.XMLSchema(str(ROOT / "tests" / "data" / "junit-10.xsd")).validate(str(tmp_path / "report" / "junit.xml"))
    suite = ET.parse(tmp_path / "report" / "junit.xml").getroot()
    assert suite.attrib["failures"] == "1"
    assert "<!doctype html>" in (tmp_path / "report" / "index.html").read_text()


def test_an_all_black_reference_gets_a_verdict_and_a_report(tmp_path: Path) -> None:
    ref, new, same = tmp_path / "ref", tmp_path / "new", tmp_path / "same"
    black = np.zeros((H, W, 4), np.float32)
    black[..., 3] = 1.0
    for frame in range(2):
        _write(ref, frame, black)
        _write(same, frame, black)
        _write(new, frame, _picture(frame) * 0.05 if frame == 1 else black)  # a fade that did not reach black
    res = motion("compare", new, ref, "--report", tmp_path / "report")
    assert res.returncode == 1 and "Traceback" not in res.stderr and "exposure" not in res.stdout + res.stderr, res.stdout + res.stderr
    assert "frame 1: different" in res.stdout and "FLIP" in res.stdout
    data = _no_nan_tokens((tmp_path / "report" / "compare.json").read_text())
    assert [f["outcome"] for f in data["frames"]] == ["identical", "different"]
    res = motion("compare", same, ref, "--flip", "all")
    assert res.returncode == 0 and "2 identical" in res.stdout, res.stdout + res.stderr


@pytest.fixture()
def golden(tmp_path: Path) -> tuple[Path, Path]:
    """(NEW, GOLDEN): three frames and their blessed set."""
    new, gold = tmp_path / "new", tmp_path / "golden"
    for frame in range(3):
        _write(new, frame, _picture(frame))
    res = motion("compare", new, gold, "--bless")
    assert res.returncode == 0, res.stderr
    return new, gold


def test_a_frame_the_manifest_does_not_list_is_no_reference(golden: tuple[Path, Path]) -> None:
    new, gold = golden
    _write(gold, 7, _picture(70) * 3.0)  # dropped into the set, not blessed
    _write(new, 7, _picture(71))
    res = motion("compare", new, gold, "--json", gold.parent / "c.json")
    assert res.returncode == 0, res.stdout + res.stderr
    data = json.loads((gold.parent / "c.json").read_text())
    assert [f["frame"] for f in data["frames"]] == [0, 1, 2] and data["unreferenced"] == [7]


def test_a_manifest_entry_leading_outside_the_set_is_refused(golden: tuple[Path, Path], tmp_path: Path) -> None:
    new, gold = golden
    pristine = tmp_path / "pristine"
    pristine.mkdir()
    shutil.copy(gold / "t.0000.exr", pristine / "t.0000.exr")
    manifest = json.loads((gold / "manifest.json").read_text())
    manifest["frames"][0]["file"] = "../pristine/t.0000.exr"
    (gold / "manifest.json").write_text(json.dumps(manifest))
    _write(gold, 0, _picture(0) * 3.0)  # the set's own file altered: never compared instead
    res = motion("compare", new, gold)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stdout + res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert "manifest.json" in res.stderr and "frames[0].file" in res.stderr and "../pristine/t.0000.exr" in res.stderr
    # a link inside the set that leads out of it is no file of the set either
    manifest["frames"][0]["file"] = "t.0000.exr"
    (gold / "manifest.json").write_text(json.dumps(manifest))
    (gold / "t.0000.exr").unlink()
    (gold / "t.0000.exr").symlink_to(pristine / "t.0000.exr")
    res = motion("compare", new, gold)
    assert res.returncode == 2 and "outside the set" in res.stderr, res.stdout + res.stderr


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


@pytest.mark.parametrize("command", ["compare", "bless"])
def test_frame_numbers_far_apart_allocate_nothing_by_their_span(tmp_path: Path, command: str) -> None:
    new, ref = tmp_path / "new", tmp_path / "ref"
    for frame in (0, 2**31):
        _write(new, frame, _picture(frame % 7))
        _write(ref, frame, _picture(frame % 7 + 1))
    args = [MOTION, "compare", str(new), str(tmp_path / "golden" if command == "bless" else ref)] + (["--bless"] if command == "bless" else [])
    t0 = time.perf_counter()
    res = subprocess.run(args, capture_output=True, text=True, timeout=120, preexec_fn=_limit_memory)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stdout + res.stderr
    assert time.perf_counter() - t0 < 60
    if command == "compare":
        assert "2 frames" in res.stdout and "2 equal within noise" in res.stdout, res.stdout
    else:
        manifest = json.loads((tmp_path / "golden" / "manifest.json").read_text())
        assert [f["frame"] for f in manifest["frames"]] == [0, 2**31]


def test_bless_with_frames_blesses_only_those(golden: tuple[Path, Path], tmp_path: Path) -> None:
    new, _ = golden
    res = motion("compare", new, tmp_path / "two", "--bless", "--frames", "0-1")
    assert res.returncode == 0, res.stderr
    manifest = json.loads((tmp_path / "two" / "manifest.json").read_text())
    assert [f["frame"] for f in manifest["frames"]] == [0, 1]
    assert sorted(p.name for p in (tmp_path / "two").glob("*.exr")) == ["t.0000.exr", "t.0001.exr"]
    res = motion("compare", new, tmp_path / "none", "--bless", "--frames", "5")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "frame 5" in res.stderr, res.stderr


def test_blessing_into_the_new_folder_itself_is_refused_before_a_write(tmp_path: Path) -> None:
    new = tmp_path / "out"
    for frame in range(2):
        _write(new, frame, _picture(frame))
    before = {p.name: p.read_bytes() for p in new.iterdir()}
    for target in (new, tmp_path / "." / "out" / ".." / "out"):
        res = motion("compare", new, target, "--bless")
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "own folder" in res.stderr, res.stderr
    assert {p.name: p.read_bytes() for p in new.iterdir()} == before  # float frames kept, no manifest


def test_report_paths_that_cannot_be_written_are_refused_before_the_work(golden: tuple[Path, Path], tmp_path: Path) -> None:
    new, gold = golden
    report = tmp_path / "report"
    (report / "junit.xml").mkdir(parents=True)
    res = motion("compare", new, gold, "--report", report)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "junit.xml" in res.stderr, res.stderr
    assert not (report / "index.html").exists() and not (report / "compare.json").exists()
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    res = motion("compare", new, gold, "--json", a_file / "under" / "c.json")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "is a file, not a folder" in res.stderr, res.stderr
    res = motion("compare", new, gold, "--html", a_file)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "a-file" in res.stderr, res.stderr


@pytest.mark.parametrize("how,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_stop_ends_a_pool_of_workers_at_once(tmp_path: Path, how: int, code: int) -> None:
    """80 frames at 640x360 with FLIP on each: some 20 s of work on two workers; a stop
    ends the command within seconds and leaves no worker behind."""
    new, ref = tmp_path / "new", tmp_path / "ref"
    new.mkdir()
    ref.mkdir()
    a, b = _write(tmp_path, 0, _picture(1, 640, 360)), _write(tmp_path, 1, _picture(2, 640, 360))
    for frame in range(80):
        os.link(a, new / f"t.{frame:04d}.exr")
        os.link(b, ref / f"t.{frame:04d}.exr")
    # SIGINT as a terminal gives it: one the test session ignores the command would too
    proc = subprocess.Popen([MOTION, "compare", str(new), str(ref), "--workers", "2", "--flip", "all"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, preexec_fn=as_from_a_terminal)
    try:
        time.sleep(4.0)  # the pool is at work
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(how)
        t0 = time.perf_counter()
        out, err = proc.communicate(timeout=30)
        stopped = time.perf_counter() - t0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == code and "Traceback" not in err, err
    assert stopped < 5.0, f"took {stopped:.1f} s to stop"
    deadline = time.perf_counter() + 10.0  # multiprocessing's forkserver and resource tracker leave when they see the command gone
    while (leftover := subprocess.run(["pgrep", "-a", "-s", str(proc.pid)], capture_output=True, text=True).stdout.strip()) and time.perf_counter() < deadline:
        time.sleep(0.2)
    assert not leftover, f"processes left: {leftover}"


def test_settings_with_nan_or_huge_numbers_in_a_header_keep_the_manifest_json(tmp_path: Path) -> None:
    new = tmp_path / "new"
    pic = _picture(0)
    write_frame(new / "t.0000.exr", pic, {"render_settings": '{"spp": NaN, "x": 1e400, "deep": ' + "[" * 5000 + "]" * 5000 + "}"})
    res = motion("compare", new, tmp_path / "golden", "--bless")
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    manifest = _no_nan_tokens((tmp_path / "golden" / "manifest.json").read_text())
    assert manifest["settings"].get("spp") is None and manifest["settings"].get("x") is None
    res = motion("compare", new, tmp_path / "golden", "--json", tmp_path / "c.json")
    assert res.returncode == 0 and "1 identical" in res.stdout, res.stdout + res.stderr
    _no_nan_tokens((tmp_path / "c.json").read_text())
