"""The kept validators (cache/validation/, scene/compiled.py) are believed only for the class
they are named for: an entry holding another record class's validator (the import list's in
the scene's place) is discarded with one warning line and made again, never handed to every
later load (which then failed with AttributeError in scene/checks.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from _support import run_motion

from motion.pipeline.scene import compiled
from motion.pipeline.scene.imports.spec import ImportList
from motion.pipeline.scene.schema import OutputSettings, Preset, RenderSettings, Scene

SCENE = ("timeline: {fps: 24, first: 0, last: 0}\nrender: {resolution: [16, 12], spp: 2}\n"
         "camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nobjects: [{name: a, shape: sphere}]\nlights: [{type: constant, radiance: 1}]\n")


def test_a_validator_knows_the_class_it_validates() -> None:
    assert compiled._root_class(compiled._made(Scene)) is Scene
    assert compiled._root_class(compiled._made(ImportList)) is ImportList
    # a preset's records; RenderSettings' own model validator wraps its record (it was
    # never kept: every --preset run built it again, 30 ms of a rerun's 0.5 s)
    for record in (Preset, RenderSettings, OutputSettings):
        assert compiled._root_class(compiled._made(record)) is record


def test_a_presets_validators_are_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    for record in (Preset, RenderSettings, OutputSettings):
        entry = compiled.entry_path(record)
        compiled._keep(entry, compiled._made(record))
        assert compiled._root_class(compiled._load(entry, record)) is record


def test_another_classes_validator_in_an_entry_is_discarded_with_a_warning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                           caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    entry = compiled.entry_path(Scene)
    compiled._keep(entry, compiled._made(ImportList))  # the import list's validator under the scene's name
    assert entry.is_file()
    assert compiled._load(entry, Scene) is None  # before: the ImportList validator, for every Scene
    warned = [r.getMessage() for r in caplog.records if str(entry) in r.getMessage()]
    assert len(warned) == 1 and "validates ImportList, not Scene" in warned[0]
    compiled._keep(entry, compiled._made(Scene))
    assert compiled._root_class(compiled._load(entry, Scene)) is Scene  # the honest entry loads


def test_validate_over_a_mismatched_entry_warns_once_and_rebuilds_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv("MOTION_CACHE_DIR", str(cache))
    entry = compiled.entry_path(Scene)
    compiled._keep(entry, compiled._made(ImportList))
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE)
    first = run_motion("validate", str(scene), env={"MOTION_CACHE_DIR": str(cache)}, timeout=60)
    assert first.returncode == 0 and "Traceback" not in first.stderr, first.stderr  # before: AttributeError, exit 1
    assert sum("kept validator discarded" in line for line in first.stderr.splitlines()) == 1
    again = run_motion("validate", str(scene), env={"MOTION_CACHE_DIR": str(cache)}, timeout=60)
    assert again.returncode == 0 and "discarded" not in again.stderr, again.stderr  # the entry was made again, right
