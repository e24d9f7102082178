"""Kept import records (scene/imports/memo.py) are believed only when they are records a
reader makes, made from the bytes their key was hashed from, and naming files the scene
could name itself or the readers converted: a record that is not a mapping or whose name is
not text, or one naming a file outside the scene's folder and the import cache, is one
warning line and the import is read again; a glTF swapped while it is read never leaves
another file's records under its digest."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any, Callable

import pytest

from motion.pipeline.errors import SceneError
from motion.pipeline.scene import load_scene

REPO = Path(__file__).resolve().parents[3]


def _walker(tmp_path: Path) -> Path:
    shot = tmp_path / "shot"
    shutil.copytree(REPO / "scenes" / "assets", shot / "assets")
    shutil.copy(REPO / "scenes" / "walker.yaml", shot / "walker.yaml")
    return shot / "walker.yaml"


def _kept(cache: Path) -> Path:
    [memo] = sorted((cache / "assets" / "imports" / "records").glob("records-*.json"))
    return memo


def _mesh(doc: dict[str, Any]) -> dict[str, Any]:
    return next(rec for rec, _ in doc["records"]["objects"] if "file" in rec)


def _forge(tmp_path: Path) -> tuple[Path, Path, Path]:
    """The walker loaded once (its records kept), the cache, the kept record's path."""
    cache = tmp_path / "cache"
    path = _walker(tmp_path)
    load_scene(path)
    return path, cache, _kept(cache)


DAMAGE: dict[str, Callable[[dict[str, Any], Path], None]] = {
    "record is 5": lambda doc, tmp: doc["records"]["objects"].__setitem__(0, [5, doc["records"]["objects"][0][1]]),
    "name is a list": lambda doc, tmp: doc["records"]["objects"][0][0].__setitem__("name", ["walker", "walker"]),
    "light record is a list": lambda doc, tmp: doc["records"]["lights"].append([[1, 2], doc["records"]["objects"][0][1]]),
    "camera name is a number": lambda doc, tmp: doc["records"]["cameras"].append([7, {"type": "perspective"}, doc["records"]["objects"][0][1]]),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_record_that_is_not_a_record_is_read_again_with_one_warning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, damage: str,
                                                                       caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    path, _, memo = _forge(tmp_path)
    first = [o.name for o in load_scene(path).scene.objects]
    doc = json.loads(memo.read_text())
    DAMAGE[damage](doc, tmp_path)
    memo.write_text(json.dumps(doc))
    caplog.clear()
    again = load_scene(path).scene  # before: AttributeError ('int' object has no attribute 'get') or TypeError (unhashable)
    assert [o.name for o in again.objects] == first
    assert sum("kept import records discarded" in r.getMessage() for r in caplog.records) == 1
    assert json.loads(memo.read_text()) != doc  # made again


def test_a_record_naming_a_file_outside_the_scene_and_the_cache_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                          caplog: pytest.LogCaptureFixture) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv("MOTION_CACHE_DIR", str(cache))
    path, _, memo = _forge(tmp_path)
    doc = json.loads(memo.read_text())
    converted = Path(_mesh(doc)["file"])
    elsewhere = tmp_path / "elsewhere" / "stolen.ply"  # a valid mesh, neither in the scene's folder nor in the cache
    elsewhere.parent.mkdir()
    shutil.copy(converted, elsewhere)
    _mesh(doc)["file"] = str(elsewhere)
    memo.write_text(json.dumps(doc))
    caplog.clear()
    scene = load_scene(path).scene  # before: loaded, naming /elsewhere/stolen.ply
    files = [str(o.file) for o in scene.objects if getattr(o, "file", None)]
    assert files and all(Path(f).resolve().is_relative_to(cache.resolve()) for f in files)
    warned = [r.getMessage() for r in caplog.records if "kept import records discarded" in r.getMessage()]
    assert len(warned) == 1 and "outside the scene's folder and the import cache" in warned[0]


def test_a_record_naming_a_file_in_the_cache_or_the_scene_folder_is_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.scene.imports import converted as import_cache

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    path, _, memo = _forge(tmp_path)
    doc = json.loads(memo.read_text())
    inside = path.parent / "assets" / "copy.ply"
    shutil.copy(_mesh(doc)["file"], inside)
    _mesh(doc)["file"] = str(inside)
    memo.write_text(json.dumps(doc))
    before = import_cache.STATS["records"]
    scene = load_scene(path).scene
    assert import_cache.STATS["records"] == before + 1  # taken from the record
    assert str(inside) in [str(o.file) for o in scene.objects if getattr(o, "file", None)]


def test_a_gltf_swapped_while_it_is_read_gives_the_records_of_the_bytes_hashed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """bad -> good -> bad: the file is malformed when it is hashed, whole while the reader
    would read it, malformed again when it is checked afterwards. The records are those of
    the bytes hashed (none: the error), in that load and in every later one; before, the
    good file's records were kept under the malformed file's digest and it validated."""
    from motion.pipeline.scene.imports import memo

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    path = _walker(tmp_path)
    glb = path.parent / "assets" / "walker.glb"
    good = glb.read_bytes()
    bad = good[: len(good) // 2]  # a GLB cut short
    glb.write_bytes(bad)
    real = memo._read_file

    def swapped_while_read(*args: Any) -> Any:
        glb.write_bytes(good)
        try:
            return real(*args)
        finally:
            glb.write_bytes(bad)

    monkeypatch.setattr(memo, "_read_file", swapped_while_read)
    with pytest.raises(SceneError):
        load_scene(path)  # before: the whole file's records
    monkeypatch.setattr(memo, "_read_file", real)
    with pytest.raises(SceneError):
        load_scene(path)  # before: those records again, from the cache, under the malformed file's digest
