"""What motion reads back from its caches and records cannot be turned against it (issue 36,
items 1, 2 and 4; pipeline/cache.py): no code from a cache runs, a kept pass or import record
is believed only if we wrote it and only for the bytes that were checked and the reader that
checked them, and a damaged record is discarded with one warning line, never a traceback or
a hang."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import stat
from pathlib import Path

import pytest
from _support import run_motion

from motion.pipeline.errors import SceneError
from motion.pipeline.scene import load_scene

REPO = Path(__file__).resolve().parents[2]
OTHER_UID = 54321  # a user who is not us (the tests may run as root: os.chown works)
OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
SCENE = ("timeline: {fps: 24, first: 0, last: 0}\nrender: {resolution: [16, 12], spp: 2}\n"
         "camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nobjects: [{name: a, shape: sphere}]\nlights: [{type: constant, radiance: 1}]\n")


class _Payload:
    """A pickle that creates `marker` when it is loaded."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (Path.touch, (self.marker,))


def _can_chown() -> bool:
    return hasattr(os, "geteuid") and os.geteuid() == 0


def _plant_validators(cache: Path, marker: Path, how: str) -> list[Path]:
    """A payload in place of every kept validator a load of the scene reads, planted `how`."""
    from motion.pipeline.scene import compiled
    from motion.pipeline.scene.imports.spec import ImportList
    from motion.pipeline.scene.schema import Scene

    old = os.environ.get("MOTION_CACHE_DIR")
    os.environ["MOTION_CACHE_DIR"] = str(cache)
    try:
        entries = [compiled.entry_path(Scene), compiled.entry_path(ImportList)]
    finally:
        if old is None:
            del os.environ["MOTION_CACHE_DIR"]
        else:
            os.environ["MOTION_CACHE_DIR"] = old
    for entry in entries:
        entry.parent.mkdir(parents=True, exist_ok=True)
        entry.write_bytes(pickle.dumps(_Payload(marker)))  # the first thing an unpickler of the entry loads
        if how == "other user":
            os.chown(entry, OTHER_UID, OTHER_UID)
        elif how == "writable by others":
            entry.chmod(0o666)
    if how == "world-writable root":
        cache.chmod(0o777)
    return entries


HOW = ["other user", "writable by others", "world-writable root"]


@pytest.mark.skipif(not _can_chown(), reason="needs to plant a file as another user")
@pytest.mark.parametrize("how", HOW)
def test_a_planted_validator_never_runs_in_validate_or_render(tmp_path: Path, how: str) -> None:
    """A pickle payload in place of the kept validators, planted by another user, writable by
    others, or in a cache root anyone may write: `motion validate` and `motion render` both
    finish (exit 0) and the payload's marker file is never made; the entry is reported in
    one warning line and made again. Before, the pickle was loaded first: the marker appeared."""
    cache, marker = tmp_path / "cache", tmp_path / "PWNED"
    cache.mkdir()
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE)
    env = {"MOTION_CACHE_DIR": str(cache)}
    _plant_validators(cache, marker, how)
    got = run_motion("validate", str(scene), env=env)
    assert got.returncode == 0, got.stderr
    assert not marker.exists()
    if how != "world-writable root":
        assert "kept validator discarded" in got.stderr and "Traceback" not in got.stderr
    _plant_validators(cache, marker, how)
    got = run_motion("render", str(scene), "--preset", "ci-smoke", "-o", str(tmp_path / "out"), "--no-progress", env=env)
    assert got.returncode == 0, got.stderr
    assert not marker.exists() and (tmp_path / "out").is_dir()


def test_a_kept_validator_names_only_what_a_validator_needs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Even an entry of ours is unpickled through an allow-list: a payload naming
    Path.touch (or os.system) is refused, discarded in one warning line, and the validator
    is made again; an honest entry loads."""
    from motion.pipeline.scene import compiled
    from motion.pipeline.scene.schema import Scene

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    entry = compiled.entry_path(Scene)
    compiled._keep(entry, compiled._made(Scene))
    assert compiled._load(entry) is not None  # ours and honest
    sources = pickle.loads(entry.read_bytes())  # the first pickle: the stamped sources
    marker = tmp_path / "PWNED"
    entry.write_bytes(pickle.dumps(sources) + pickle.dumps(_Payload(marker)))
    assert compiled._load(entry) is None and not marker.exists()


@pytest.mark.parametrize("damage", ["fifo", "truncated", "not a pickle"])
def test_a_damaged_validator_is_made_again_and_never_hangs(tmp_path: Path, damage: str) -> None:
    """A FIFO, a cut-short entry or bytes that are no pickle in place of a kept validator:
    `motion validate` finishes at once (a FIFO is never opened for reading) with exit 0."""
    cache = tmp_path / "cache"
    cache.mkdir()
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE)
    entries = _plant_validators(cache, tmp_path / "PWNED", "ours")
    for entry in entries:
        entry.unlink()
        if damage == "fifo":
            os.mkfifo(entry)
        else:
            entry.write_bytes(b"\x80\x05garbage" if damage == "not a pickle" else pickle.dumps([(__file__, 0, 0)])[:5])
    got = run_motion("validate", str(scene), env={"MOTION_CACHE_DIR": str(cache)}, timeout=60)
    assert got.returncode == 0 and "Traceback" not in got.stderr, got.stderr
    assert stat.S_ISREG(entries[0].lstat().st_mode)  # the scene's validator, made again in place


# --- kept asset passes ---------------------------------------------------------------------------

def _mesh_scene(folder: Path, mesh: str) -> Path:
    scene = folder / "s.yaml"
    scene.write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\n"
                     f"objects: [{{name: a, shape: mesh, file: {mesh}}}]\nlights: [{{type: constant, radiance: 1}}]\n")
    return scene


def test_a_pass_is_kept_for_the_reader_that_checked_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An OBJ that passed does not make byte-identical `.ply` pass: the suffix picks the
    reader, and it is part of the pass's key (before, the .ply validated and every frame
    then failed)."""
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "tri.obj").write_text(OBJ)
    load_scene(_mesh_scene(tmp_path, "tri.obj"))
    shutil.copy(tmp_path / "tri.obj", tmp_path / "tri.ply")
    with pytest.raises(SceneError, match="tri.ply"):
        load_scene(_mesh_scene(tmp_path, "tri.ply"))


def test_a_file_swapped_between_its_hash_and_its_check_is_never_passed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A damaged PNG is hashed; before its check reads it, a good PNG takes its place: the
    check reads the bytes that were hashed (a private copy), so it fails, and no pass is
    kept for the damaged bytes: put back, they fail again (before, the good file's pass was
    kept under the damaged bytes' hash and they validated ever after)."""
    from PIL import Image

    import motion.pipeline.images as images

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    tex = tmp_path / "tex.png"
    Image.new("RGB", (4, 4), (200, 10, 10)).save(tex)
    good = tex.read_bytes()
    bad = good[:40]
    tex.write_bytes(bad)
    real = images.check_image

    def swapped(path: Path):  # type: ignore[no-untyped-def]
        tex.write_bytes(good)  # the swap, after the hash, before the read
        return real(path)

    scene = tmp_path / "s.yaml"
    scene.write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nmaterials: [{name: m, type: diffuse, color: {file: tex.png}}]\n"
                     "objects: [{name: a, shape: sphere, material: m}]\nlights: [{type: constant, radiance: 1}]\n")
    monkeypatch.setattr(images, "check_image", swapped)
    with pytest.raises(SceneError, match="tex.png"):
        load_scene(scene)
    monkeypatch.setattr(images, "check_image", real)
    tex.write_bytes(bad)
    with pytest.raises(SceneError, match="tex.png"):
        load_scene(scene)


@pytest.mark.skipif(not _can_chown(), reason="needs to plant a file as another user")
@pytest.mark.parametrize("how", ["other user", "writable by others"])
def test_a_planted_pass_does_not_make_a_malformed_obj_validate(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, how: str) -> None:
    """A pass for a malformed OBJ's bytes, planted by another user (or writable by others),
    is no pass: the OBJ is decoded and refused."""
    from motion.pipeline.scene.files import file_digest
    from motion.pipeline.scene import checked

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")  # faces name vertices that are not there
    kept = checked._key("mesh", ".obj", file_digest(bad))
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"")
    if how == "other user":
        os.chown(kept, OTHER_UID, OTHER_UID)
    else:
        kept.chmod(0o666)
    with pytest.raises(SceneError, match="bad.obj"):
        load_scene(_mesh_scene(tmp_path, "bad.obj"))
    assert checked.STORE.stats["refused"] >= 1


# --- kept import records -------------------------------------------------------------------------

def _walker(tmp_path: Path) -> Path:
    shot = tmp_path / "shot"
    shutil.copytree(REPO / "scenes" / "assets", shot / "assets")
    shutil.copy(REPO / "scenes" / "walker.yaml", shot / "walker.yaml")
    return shot / "walker.yaml"


def _records(cache: Path) -> list[Path]:
    return sorted((cache / "assets" / "imports" / "records").glob("records-*.json"))


@pytest.mark.parametrize("damage", ["deep", "list", "wrong fields", "fifo", "other user"])
def test_a_damaged_or_foreign_import_record_is_read_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, damage: str,
                                                          caplog: pytest.LogCaptureFixture) -> None:
    """A kept import record nested 100,000 deep, not a mapping, with wrong fields, a FIFO,
    or planted by another user: the import is read again (the same scene), a damaged one is
    one warning line, and the load never hangs or fails."""
    from motion.pipeline.scene.imports import converted as import_cache

    if damage == "other user" and not _can_chown():
        pytest.skip("needs to plant a file as another user")
    cache = tmp_path / "cache"
    monkeypatch.setenv("MOTION_CACHE_DIR", str(cache))
    path = _walker(tmp_path)
    first = load_scene(path).scene
    [memo] = _records(cache)
    doc = json.loads(memo.read_text())
    memo.unlink()
    if damage == "deep":
        memo.write_text("[" * 100_000 + "]" * 100_000)
    elif damage == "list":
        memo.write_text("[1, 2]")
    elif damage == "wrong fields":
        memo.write_text(json.dumps({"read": [], "records": 7}))
    elif damage == "fifo":
        os.mkfifo(memo)
    else:
        doc["records"]["objects"] = doc["records"]["objects"][:1]  # fewer objects than the file has
        memo.write_text(json.dumps(doc))
        os.chown(memo, OTHER_UID, OTHER_UID)
    before = import_cache.STATS["records"]
    again = load_scene(path).scene
    assert import_cache.STATS["records"] == before  # read again, not taken from the record
    assert [o.name for o in again.objects] == [o.name for o in first.objects]
    if damage in ("deep", "list", "wrong fields"):
        assert sum("kept import records discarded" in r.getMessage() for r in caplog.records) == 1


def test_an_import_swapped_while_it_is_read_is_not_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The glTF file is hashed, then another file takes its place before the reader reads
    it: the reader parses the bytes that were hashed (memo.read_import reads the file once),
    so the records kept under the first file's hash are the first file's, and the other
    file, loaded in its turn, gets its own."""
    from motion.pipeline.scene.imports import converted as import_cache
    from motion.pipeline.scene.imports import memo

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    path = _walker(tmp_path)
    glb = path.parent / "assets" / "walker.glb"
    original = glb.read_bytes()
    length = int.from_bytes(original[12:16], "little")
    doc = json.loads(original[20 : 20 + length])
    names = [n["name"] for n in doc["nodes"] if n.get("name")]
    swapped = original.replace(f'"{names[0]}"'.encode(), f'"{"Q" * len(names[0])}"'.encode(), 1)  # same length: still a whole GLB
    real = memo._read_file

    def swap_then_read(*args):  # type: ignore[no-untyped-def]
        glb.write_bytes(swapped)
        return real(*args)

    monkeypatch.setattr(memo, "_read_file", swap_then_read)
    assert not any("QQQ" in o.name for o in load_scene(path).scene.objects)  # the bytes hashed, not the file swapped in
    monkeypatch.setattr(memo, "_read_file", real)
    glb.write_bytes(original)
    before = import_cache.STATS["records"]
    objects = [o.name for o in load_scene(path).scene.objects]
    assert import_cache.STATS["records"] == before + 1 and not any("QQQ" in n for n in objects)  # kept, and the first file's
    glb.write_bytes(swapped)
    assert any("QQQ" in o.name for o in load_scene(path).scene.objects)  # the other file: its own records


# --- the cost history ----------------------------------------------------------------------------

@pytest.mark.parametrize("damage", ["list", "string number", "nan", "negative", "deep", "fifo"])
def test_a_damaged_cost_history_is_discarded_and_written_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, damage: str,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """estimates.json of the wrong type, with a bad number, nested deep or a FIFO: the
    estimate uses the built-in figures with one warning line (no traceback, no hang) and the
    next finished run writes a sound history in its place."""
    from motion.pipeline.shot import estimate

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path))
    run = {"settings_hash": "h", "samples": 100, "warm_s": 0.1, "cold_extra_s": 0.1, "startup_s": 0.1}
    bad = {"string number": "0.1x", "nan": float("nan"), "negative": -1.0}
    path = estimate.history_path()
    if damage == "list":
        path.write_text("[]")
    elif damage == "deep":
        path.write_text("{\"scenes\": " + "[" * 50_000 + "]" * 50_000 + "}")
    elif damage == "fifo":
        os.mkfifo(path)
    else:
        path.write_text(json.dumps({"version": 2, "scenes": {"s": [{**run, "warm_s": bad[damage]}]}}))
    got = estimate.estimate("s", "h", 100, 4, 1)
    assert got["basis"].startswith("built-in") and sum("cost history discarded" in r.getMessage() for r in caplog.records) == 1
    estimate.record("s", "h", 100, {"frames": [{"status": "rendered", "render_s": 0.2, "cold": False}], "workers": ["w"], "totals": {"farm_s": 1.0}})
    assert stat.S_ISREG(path.stat().st_mode) and estimate.estimate("s", "h", 100, 4, 1)["basis"].startswith("this scene")


def test_a_fifo_in_place_of_a_pass_or_a_converted_asset_is_made_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A FIFO where a kept pass or a converted mesh would be: never opened (no hang), not
    a hit, and replaced by the entry made again."""
    from motion.pipeline.scene.files import file_digest
    from motion.pipeline.render.translate import assets
    from motion.pipeline.scene import checked
    from motion.pipeline.variant import activate

    activate("auto", quiet=True)  # mesh_file converts through Mitsuba
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "tri.obj").write_text(OBJ)
    kept = checked._key("mesh", ".obj", file_digest(tmp_path / "tri.obj"))
    kept.parent.mkdir(parents=True)
    os.mkfifo(kept)
    load_scene(_mesh_scene(tmp_path, "tri.obj"))
    assert stat.S_ISREG(kept.lstat().st_mode)  # the pass, kept in its place
    made = assets.mesh_file(tmp_path / "tri.obj")
    made.unlink()
    os.mkfifo(made)
    assert assets.mesh_file(tmp_path / "tri.obj") == made and stat.S_ISREG(made.lstat().st_mode) and made.stat().st_size > 0
