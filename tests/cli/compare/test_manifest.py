"""A golden set's manifest is read as hostile input: a damaged one (a number out of range,
nesting a hundred thousand deep, a wrong type anywhere, a huge file, a folder or a FIFO
where the file should be) is one located line and exit 2, never a traceback or a hang.
A fuzz over the manifest's types, depths and sizes finds nothing else."""

from __future__ import annotations

import copy
import json
import os
import random
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from farm_util import motion
from motion.pipeline.compare import compare_sequences, read_manifest
from motion.pipeline.compare.golden import MAX_MANIFEST_BYTES
from motion.pipeline.errors import MotionError
from motion.pipeline.frame_output import write_frame


@pytest.fixture(scope="module")
def blessed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict]:
    """(NEW, GOLDEN, its manifest): two 16x8 frames and their blessed set."""
    root = tmp_path_factory.mktemp("manifest")
    rng = np.random.default_rng(0)
    for frame in range(2):
        pic = (0.5 + 0.05 * rng.standard_normal((8, 16, 4))).astype(np.float32)
        write_frame(root / "new" / f"t.{frame:04d}.exr", pic, {"seed": frame, "render_settings": json.dumps({"spp": 4})})
    res = motion("compare", root / "new", root / "golden", "--bless")
    assert res.returncode == 0, res.stderr
    return root / "new", root / "golden", json.loads((root / "golden" / "manifest.json").read_text())


@pytest.mark.parametrize("text,where", [
    ('"frame": 1e400', "frames[0].frame"),
    ('"frame": 0.0', "frames[0].frame"),
    ('"frame": true', "frames[0].frame"),
    ('"frame": 36893488147419103232', "frames[0].frame"),
    ('"settings": [1, 2]', "settings"),
    ('"resolution": "16x8"', "resolution"),
    ('"sha256": 5', "frames[0].sha256"),
    ('"file": ["t.0000.exr"]', "frames[0].file"),
])
def test_a_damaged_manifest_is_one_located_line(blessed: tuple[Path, Path, dict], tmp_path: Path, text: str, where: str) -> None:
    new, golden, manifest = blessed
    key = text.split(":")[0].strip('"')
    damaged = copy.deepcopy(manifest)
    target = damaged["frames"][0] if where.startswith("frames[0]") else damaged
    target[key] = "@@"
    folder = tmp_path / "golden"
    folder.mkdir()
    for f in golden.glob("*.exr"):
        (folder / f.name).write_bytes(f.read_bytes())
    (folder / "manifest.json").write_text(json.dumps(damaged).replace('"' + key + '": "@@"', text))
    res = motion("compare", new, folder)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(folder / "manifest.json") in lines[0] and where in lines[0], lines


def test_deep_nesting_huge_files_folders_and_fifos_are_refused(blessed: tuple[Path, Path, dict], tmp_path: Path) -> None:
    new, golden, _ = blessed
    folder = tmp_path / "golden"
    folder.mkdir()
    for f in golden.glob("*.exr"):
        (folder / f.name).write_bytes(f.read_bytes())
    manifest = folder / "manifest.json"

    def sparse_and_huge() -> None:
        with manifest.open("w") as f:
            f.truncate(MAX_MANIFEST_BYTES + 1)

    for damage, said in ((lambda: manifest.write_text("[" * 100000), "manifest"),
                         (lambda: manifest.write_text('{"format": "motion-golden/1", "frames": ' + "[" * 100000 + "]" * 100000 + "}"), "manifest"),
                         (lambda: manifest.mkdir(), "not a regular file"),
                         (lambda: os.mkfifo(manifest), "not a regular file"),
                         (sparse_and_huge, "more than a golden manifest holds")):
        if manifest.is_dir():
            manifest.rmdir()
        elif manifest.exists() or manifest.is_symlink():
            manifest.unlink()
        damage()
        res = motion("compare", new, folder, timeout=60)
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and "manifest.json" in lines[0] and said in lines[0], lines


HOSTILE: list[Any] = [None, True, -1, 0, 2**70, -(2**70), 1.5, float("inf"), "", "x" * 5000, "../x.exr", "/etc/passwd", "t.0000.exr",
                      [], [1, 2], {}, {"a": 1}, [[[[[]]]]], {"frame": 0}]


def _deep(depth: int) -> Any:
    value: Any = 0
    for i in range(depth):
        value = [value] if i % 2 else {"k": value}
    return value


def _mutate(doc: dict, rng: random.Random) -> dict:
    """One random change: a value of another type, size or depth anywhere in the document."""
    doc = copy.deepcopy(doc)
    paths: list[tuple[Any, Any]] = []

    def walk(node: Any) -> None:
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
        for k, v in items:
            paths.append((node, k))
            walk(v)

    walk(doc)
    node, key = rng.choice(paths)
    choice = rng.random()
    if choice < 0.7:
        node[key] = copy.deepcopy(rng.choice(HOSTILE))
    elif choice < 0.85:
        node[key] = _deep(rng.choice([10, 150, 900]))
    elif isinstance(node, dict):
        del node[key]
    else:
        node[key] = [node[key]] * rng.choice([2, 1000])
    return doc


def test_fuzz_the_manifest_finds_no_traceback(blessed: tuple[Path, Path, dict], tmp_path: Path) -> None:
    """300 damaged manifests, read in this process: each is read (a harmless change) or a
    MotionError, never another exception; one compare per outcome kind through the CLI."""
    new, golden, manifest = blessed
    folder = tmp_path / "golden"
    folder.mkdir()
    for f in golden.glob("*.exr"):
        (folder / f.name).write_bytes(f.read_bytes())
    rng = random.Random(46)
    outcomes = {"read": 0, "refused": 0}
    for _ in range(300):
        doc = _mutate(manifest, rng)
        try:
            text = json.dumps(doc)
        except (ValueError, RecursionError):
            continue
        (folder / "manifest.json").write_text(text)
        try:
            read_manifest(folder)
            compare_sequences(new, folder, workers=1)
            outcomes["read"] += 1
        except MotionError as err:
            assert "\n" not in str(err) and str(folder / "manifest.json") in str(err) or "t.000" in str(err), str(err)
            outcomes["refused"] += 1
    assert outcomes["refused"] > 100 and outcomes["read"] > 10, outcomes
