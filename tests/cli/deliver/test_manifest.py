"""The deliverables' manifest against hostile input: a manifest renumbered to the last
version, a manifest that is a folder, a disk that fills while the manifest is written,
`--deliver-frames` reversed. Each ends in one line (exit 2 for bad input, 4 for the disk)
and leaves every version and the manifest as they were."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Iterator

import pytest
import yaml

from farm_util import SCENE, TINY, motion

pytestmark = pytest.mark.render


def _scene(tmp_path: Path, last: int = 3) -> Path:
    doc = yaml.safe_load(SCENE.read_text())
    doc["timeline"]["last"] = last
    path = tmp_path / "shot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _recolour_floor(scene: Path, value: float) -> None:
    doc = yaml.safe_load(scene.read_text())
    next(m for m in doc["materials"] if m["name"] == "floor")["color"] = value
    scene.write_text(yaml.safe_dump(doc))


def _one_error(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


def _tree(folder: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def test_a_manifest_renumbered_to_the_last_version_says_what_to_move(tmp_path: Path) -> None:
    """A manifest whose version is renumbered v999999999: the next version was
    v1000000000, which no later run read back (every run then discarded the manifest and
    exited 2 "appeared while it was being made", forever). Now the run says which version
    is the last a name holds and what to move, exit 2, nothing published; once the entry
    is moved away, the next run makes a version again."""
    scene, out = _scene(tmp_path), tmp_path / "out"
    args = ["render", scene, "-o", out, *TINY, "--deliver", "contact"]
    assert motion(*args).returncode == 0
    path = out / "deliver" / "manifest.json"
    doc = json.loads(path.read_text())
    entry = doc["deliverables"]["contact"]
    entry["versions"] = {"v999999999": entry["versions"]["v001"]}
    entry["latest"] = "v999999999"
    path.write_text(json.dumps(doc))
    before = _tree(out / "deliver")
    _recolour_floor(scene, 0.2)
    for _ in range(2):  # the same answer each time, never a state of its own making
        res = motion(*args)
        assert res.returncode == 2, res.stderr
        line = _one_error(res.stderr)
        assert "v999999999" in line and "v001 to v999999999" in line and "move the contact versions out of" in line, line
        assert _tree(out / "deliver") == before
    path.unlink()  # what the line asks: the entry moved away
    res = motion(*args)
    assert res.returncode == 0, res.stderr
    assert (out / "deliver" / "farm-tiny_contact_v002.png").is_file()


def test_a_manifest_that_is_a_folder_is_refused_before_the_first_frame(tmp_path: Path) -> None:
    """deliver/manifest.json a folder: v002 was published, then an IsADirectoryError
    traceback. Now exit 2 before the first frame, naming it; no frame re-rendered, no
    version published."""
    scene, out = _scene(tmp_path), tmp_path / "out"
    args = ["render", scene, "-o", out, *TINY, "--deliver", "contact"]
    assert motion(*args).returncode == 0
    path = out / "deliver" / "manifest.json"
    path.unlink()
    path.mkdir()
    (path / "keep.txt").write_text("not ours")
    frames = {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")}
    _recolour_floor(scene, 0.2)
    res = motion(*args, "--overwrite")
    assert res.returncode == 2, res.stderr
    line = _one_error(res.stderr)
    assert f"{path} is a folder" in line, line
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")} == frames
    assert sorted(p.name for p in (out / "deliver").iterdir()) == ["farm-tiny_contact_v001.png", "manifest.json"]
    assert (path / "keep.txt").read_text() == "not ours"


def test_deliver_frames_reversed_is_reported_as_deliver_frames(tmp_path: Path) -> None:
    """`--deliver-frames 3-1` was reported as "--frames: range '3-1' is reversed"."""
    res = motion("render", _scene(tmp_path), "-o", tmp_path / "out", *TINY, "--deliver", "contact", "--deliver-frames", "3-1")
    assert res.returncode == 2, res.stderr
    line = _one_error(res.stderr)
    assert line.startswith("error: --deliver-frames: range '3-1' is reversed"), line
    assert "--frames:" not in line


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 2 MiB tmpfs (a real disk that fills), as tests/cli/output/test_disk_faults.py mounts one."""
    disk = tmp_path / "disk"
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a tmpfs (the fault is a real full file system)")
    disk.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)], capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def _leave_free(disk: Path, free: int) -> None:
    """Fill `disk` until about `free` bytes are left (a file `fill`)."""
    fill = disk / "fill"
    try:
        with open(fill, "wb") as fh:
            while True:
                fh.write(b"\0" * 4096)
                fh.flush()
    except OSError:
        pass
    os.truncate(fill, max(0, fill.stat().st_size - free))


def test_a_disk_that_fills_while_the_manifest_is_written_publishes_nothing(small_disk: Path, tmp_path: Path) -> None:
    """The manifest is larger than the room left on the disk (a long history) and the new
    sheet is not: the sheet was published, then the manifest's write failed (exit 4), so
    `..._v001.png` was there and no manifest said what it was. Now the version and the
    manifest are written in the staging folder first and published by renames, manifest
    last: exit 4 naming the manifest, the deliver folder as it was, no temporary left;
    once there is room the same command makes the version."""
    scene, out = _scene(tmp_path), small_disk / "out"
    assert motion("render", scene, "-o", out, *TINY, "--deliver", "contact").returncode == 0
    path = out / "deliver" / "manifest.json"
    doc = json.loads(path.read_text())
    record = doc["deliverables"]["contact"]["versions"]["v001"]
    # a long history: another deliverable's 400 versions (their outputs long gone)
    doc["deliverables"]["contact@0-1"] = {"versions": {f"v{n:03d}": record for n in range(1, 401)}, "format": "contact", "part": "0-1", "latest": "v400"}
    path.write_text(json.dumps(doc, indent=2))
    assert path.stat().st_size > 700_000
    before = _tree(out / "deliver")
    _leave_free(small_disk, 300_000)
    args = ["render", scene, "-o", out, *TINY, "--deliver", "contact", "--deliver-frames", "0-2"]
    res = motion(*args)
    assert res.returncode == 4, res.stderr
    line = _one_error(res.stderr)
    assert "No space left on device" in line and "manifest" in line, line
    assert _tree(out / "deliver") == before
    (small_disk / "fill").unlink()
    res = motion(*args)
    assert res.returncode == 0, res.stderr
    assert (out / "deliver" / "farm-tiny_contact_0-2_v001.png").is_file()
    assert json.loads(path.read_text())["deliverables"]["contact@0-2"]["latest"] == "v001"
