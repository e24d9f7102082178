"""Hostile input, round 4 (issue 36): signals and neighbours, bad input found late, the two
YAML readers, timecode as studios write it, import and size budgets, a damaged run report.
Each test fails on the code before the change it covers; each case ends as the README
promises: a located one-line error, exit 2, before any work (or a render that works)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.cli.test_hostile_input import BASE as HOSTILE_BASE
from tests.scene.test_validation import _parse_both
from farm_util import SCENE, SLOW, TINY, frames_in, leftovers, motion, report, start_motion, wait_for, worker_pids
from motion.pipeline.errors import OutputInUseError
from motion.pipeline.farm import claims
from motion.pipeline.frame_output import is_complete


# --- 8. signals and neighbours -------------------------------------------------------------


def _alive(pid: int) -> bool:
    """Whether `pid` is a live process (a zombie is not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def test_sigterm_ends_a_render_like_ctrl_c_with_exit_143(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-13", "--workers", "2", "--chunk-size", "2", *SLOW)
    wait_for(lambda: len(frames_in(out)) >= 1, 60, "a first frame")
    workers = worker_pids(proc.pid)
    assert workers
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 143, (proc.returncode, stderr)  # before: killed by the signal (-15), no report
    assert stderr.strip().splitlines()[-1] == "terminated" and "Traceback" not in stderr
    rep = report(out)
    assert rep["interrupted"] is True
    wait_for(lambda: not any(_alive(p) for p in workers), 10, "the workers to stop")
    done = {p.name for p in frames_in(out)}
    time.sleep(1.0)
    assert {p.name for p in frames_in(out)} == done  # no worker writes on after the stop
    assert all(is_complete(out / name) for name in done) and 1 <= len(done) < 14
    assert not leftovers(out)  # no partial files, no claims, no run lock


def _plant_lock(out: Path, pid: int, version: str, run_id: str = "planted-run", at: float | None = None) -> Path:
    folder = out / claims.CLAIM_DIR
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{claims.RUN_LOCK_PREFIX}{run_id}{claims.RUN_LOCK_SUFFIX}"
    t = time.time() if at is None else at
    path.write_text(json.dumps({"run_id": run_id, "host": socket.gethostname(), "pid": pid, "scene": "/farm/other/shot.yaml", "version": version, "time": t}))
    return path


def test_another_version_rendering_into_the_folder_is_refused_naming_it(tmp_path: Path) -> None:
    out = tmp_path / "out"
    # a live run (this test's own process) of another version holds the folder
    _plant_lock(out, os.getpid(), "another-version")
    res = motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY)
    assert res.returncode == 2, res.stderr
    line = res.stderr.strip()
    assert line.count("\n") == 0 and "another version" in line and f"pid {os.getpid()}" in line and socket.gethostname() in line, line
    assert "/farm/other/shot.yaml" in line
    assert not frames_in(out)
    # once that run is gone (its pid no longer lives here), the folder is free again
    dead = subprocess.Popen(["true"])
    dead.wait()
    (out / claims.CLAIM_DIR / "run-planted-run.lock").unlink()
    _plant_lock(out, dead.pid, "another-version", run_id="dead-run")
    res = motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY)
    assert res.returncode == 0, res.stderr
    assert len(frames_in(out)) == 2 and not leftovers(out)


def test_two_versions_at_once_one_goes_on_the_other_refuses(tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = start_motion("render", SCENE, "-o", out, "--frames", "0-7", "--workers", "1", "--chunk-size", "2", *SLOW)
    wait_for(lambda: any((out / claims.CLAIM_DIR).glob("run-*.lock")) if (out / claims.CLAIM_DIR).is_dir() else False, 60, "the first run's lock")
    second = motion("render", SCENE, "-o", out, "--frames", "0-7", "--resolution", "96x72", "--spp", "2", "--no-progress", "--resume")
    assert second.returncode == 2 and "another version" in second.stderr and f"pid {first.pid}" in second.stderr, second.stderr
    _, stderr = first.communicate(timeout=120)
    assert first.returncode == 0, stderr
    assert len(frames_in(out)) == 8 and not leftovers(out)
    assert motion("render", SCENE, "-o", out, "--frames", "0-7", *SLOW, "--check").returncode == 0  # one version only


def test_run_locks_of_one_version_share_and_of_two_give_way_by_order(tmp_path: Path) -> None:
    me = claims.Claimant.here("run-b")
    # the same version (a shard, a second machine helping) shares the folder
    _plant_lock(tmp_path, os.getpid(), "v1", run_id="run-a")
    lock = claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")
    claims.release_run_lock(lock)
    assert not lock.path.exists()
    # two versions that started together: the later lock gives way, the earlier goes on
    later = _plant_lock(tmp_path, os.getpid(), "v2", run_id="run-c", at=time.time() + 60)
    lock = claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")  # run-a is v1; run-c is later
    claims.release_run_lock(lock)
    later.unlink()
    _plant_lock(tmp_path, os.getpid(), "v2", run_id="run-d", at=time.time() - 1)
    with pytest.raises(OutputInUseError):
        claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")
    assert not (tmp_path / claims.CLAIM_DIR / "run-run-b.lock").exists()  # the refused run leaves no lock
    # garbage in a lock file (not JSON, wrong types) is no lock, once past the write grace
    junk = tmp_path / claims.CLAIM_DIR / "run-junk.lock"
    for body in (b"\xff\xfe", b"[1,2]", b'{"run_id": 5, "pid": "x"}', b'{"run_id": "r", "pid": true}'):
        junk.write_bytes(body)
        old = time.time() - 60
        os.utime(junk, (old, old))
        (tmp_path / claims.CLAIM_DIR / "run-run-d.lock").unlink(missing_ok=True)
        claims.release_run_lock(claims.take_run_lock(tmp_path, me, "shot.yaml", "v1"))
        assert not junk.exists()


# --- 5. bad input found late -----------------------------------------------------------------

BASE = HOSTILE_BASE.replace("last: 2", "last: 1")  # two frames


@pytest.mark.parametrize("extra, where", [
    ('output: {owner: "ann\\ud800"}\n', "7:17: output.owner"),
    ('output: {comments: "x\\udfff y"}\n', "7:20: output.comments"),
    ('output: {directory: "out\\udc80"}\n', "7:21: output.directory"),
    ('"extra\\ud800": 1\n', "7:1: extra\\ud800"),
])
def test_a_lone_surrogate_is_a_located_error_at_validation(tmp_path: Path, extra: str, where: str) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE + extra)
    res = motion("validate", scene)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert f"s.yaml:{where}: a lone surrogate" in res.stderr.splitlines()[0], res.stderr
    res = motion("render", scene, "-o", tmp_path / "out")  # before: every frame failed with UnicodeEncodeError
    assert res.returncode == 2 and not (tmp_path / "out").exists(), res.stderr


def test_names_that_are_not_utf8_are_refused_before_any_frame(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    odd = os.fsdecode(b"sc\xffene.yaml")
    (tmp_path / odd).write_text(BASE)
    for argv, what in (([scene, "-o", tmp_path / os.fsdecode(b"out\xff")], "output folder"), ([tmp_path / odd, "-o", tmp_path / "o2"], "scene file")):
        res = motion("render", *argv)
        assert res.returncode == 2 and f"error: {what} " in res.stderr and "\\xff" in res.stderr and "not UTF-8" in res.stderr, res.stderr
    assert sorted(os.listdir(tmp_path)) == sorted(["s.yaml", odd])


def test_deliver_over_negative_frames_is_made(tmp_path: Path) -> None:
    """Frames below 0 are read by every tool (docs/telecine.md): the deliverable of a
    timeline from -2 is made of its four frames (it was refused before the first frame)."""
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("first: 0, last: 1", "first: -2, last: 1"))
    res = motion("render", scene, "-o", tmp_path / "out", "--deliver", "contact")
    assert res.returncode == 0, res.stderr
    made = json.loads((tmp_path / "out" / "deliver" / "manifest.json").read_text())["deliverables"]["contact"]["versions"]["v001"]
    assert made["frames"] == "-2..1" and sorted(map(int, made["frame_files"])) == [-2, -1, 0, 1]


def test_an_ocio_config_that_is_not_a_regular_file_is_refused_not_waited_on(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    fifo = tmp_path / "config.ocio"
    os.mkfifo(fifo)
    for config, why in ((fifo, "not a regular file"), (tmp_path, "is a folder")):
        res = motion("render", scene, "-o", tmp_path / "out", "--deliver", "review", "--ocio", config, timeout=60)  # before: hung in OCIO's reader
        assert res.returncode == 2 and why in res.stderr and "OCIO config" in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv", [
    ["render", "{scene}", "-o", ""],
    ["render", "{scene}", "-o", "  "],
    ["render", "{scene}", "--report", ""],
    ["bake", "{scene}", "-o", ""],
    ["telecine", "{tmp}", "-o", ""],
])
def test_an_empty_output_path_is_refused_not_the_current_folder(tmp_path: Path, argv: list[str]) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    work = tmp_path / "cwd"
    work.mkdir()
    res = motion(*[a.format(scene=scene, tmp=tmp_path) for a in argv], cwd=work)
    assert res.returncode == 2 and "an empty path" in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert not os.listdir(work)  # before: frames and report in the current folder, exit 0


# --- 6. two YAML readers, one meaning (the cases found are in test_scene_validation.HOSTILE_YAML) --

BOM = "\ufeff"


_PIECES = ["\t", BOM, "!", " ", "\n", ":", "- ", "#", "'", '"', "[", "]", "{", "}", ",", "&a ", "*a", "? ", "|", ">", "%", "\r", "\\"]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 10_000), st.sampled_from(_PIECES)), min_size=1, max_size=4))
def test_fuzz_the_two_readers_agree_on_every_mutation(monkeypatch: pytest.MonkeyPatch, edits: list[tuple[int, str]]) -> None:
    """A scene with tabs, BOMs, tags and YAML punctuation put anywhere: libyaml's fast path
    and PyYAML alone give the same data and positions, or the same located problems."""
    text = BASE + "materials: [{name: m, type: diffuse, color: 0.5}]\n"
    for at, piece in edits:
        at %= len(text) + 1
        text = text[:at] + piece + text[at:]
    fast, slow = _parse_both(text, monkeypatch)
    assert fast == slow, text


# --- 7. timecode as studios write it ----------------------------------------------------------


@pytest.mark.parametrize("written, rate", [
    ("29.97", "30000/1001"), ("59.94", "60000/1001"), ("23.976", "24000/1001"), ("23.98", "24000/1001"),
    ('"29.97"', "30000/1001"), ("119.88", "120000/1001"), ("47.952", "48000/1001"),
    ("29.9", "299/10"), ("30", "30"), ("29.971", "29971/1000"), ('"30000/1001"', "30000/1001"),
])
def test_ntsc_rates_written_as_decimals_are_the_exact_ratio(tmp_path: Path, written: str, rate: str) -> None:
    from motion.pipeline.scene import load_scene

    (tmp_path / "s.yaml").write_text(BASE.replace("fps: 24", f"fps: {written}"))
    loaded = load_scene(tmp_path / "s.yaml")
    assert loaded.scene.timeline.fps == rate  # before: 29.97 was 2997/100


@pytest.mark.parametrize("fps, frame, code", [("29.97", 1800, "00:01:00;02"), ("59.94", 3600, "00:01:00;04"), ("29.97", 17982, "00:10:00;00")])
def test_frames_at_29_97_and_59_94_carry_drop_frame_timecode(tmp_path: Path, fps: str, frame: int, code: str) -> None:
    from motion.pipeline.frame_output import header_timecode, read_header

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("fps: 24, first: 0, last: 1", f"fps: {fps}, first: {frame}, last: {frame}"))
    res = motion("render", scene, "-o", tmp_path / "out")
    assert res.returncode == 0, res.stderr
    (path,) = frames_in(tmp_path / "out")
    assert header_timecode(read_header(path)) == code  # before: non-drop at 2997/100


def test_export_of_frames_below_zero_is_whole(tmp_path: Path) -> None:
    """Frames below 0 are read by every tool: export and view write all four images (before
    the reader ignored them: 2 of 4 images, exit 0; then they were refused)."""
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("first: 0, last: 1", "first: -2, last: 1"))
    assert motion("render", scene, "-o", tmp_path / "out").returncode == 0
    for command in ("export", "view"):
        res = motion(command, tmp_path / "out", "-o", tmp_path / command / "index.html" if command == "view" else tmp_path / command)
        assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "export").glob("*.png"))[:2] == ["s.-0001.png", "s.-0002.png"]
    assert len(list((tmp_path / "export").glob("*.png"))) == 4 and len(list((tmp_path / "view" / "frames").glob("*.jpg"))) == 4


# --- 9. import and size budgets ---------------------------------------------------------------

TRI = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header claims `width` x `height` (its one row of data is all there is)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(b"\x00\x00\x00\x00")) + chunk(b"IEND", b"")


def _gltf(folder: Path, edit: Any = None, keys: int = 0, texture: bytes | None = None) -> Path:
    """A one-triangle .gltf (buffer as a data URI) in `folder` with a scene importing it;
    `keys` animation keys on its node, `texture` an embedded base-colour image, then
    `edit(document)` on its JSON."""
    import sys

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    tri = np.array(TRI, float)
    prim: dict[str, Any] = {"attributes": {"POSITION": b.accessor(tri, bounds=True), "TEXCOORD_0": b.accessor(tri[:, :2])}, "indices": b.accessor(np.array([0, 1, 2]), dtype="uint16")}
    if texture is not None:
        b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": b.image(texture)}}}]
        prim["material"] = 0
    b.gltf["meshes"].append({"name": "m", "primitives": [prim]})
    b.gltf["scenes"][0]["nodes"].append(b.node(name="tri", mesh=0))
    if keys:
        times, values = b.accessor(np.arange(keys, dtype=np.float32) / 24), b.accessor(np.zeros((keys, 3), np.float32))
        b.gltf["animations"] = [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}], "samplers": [{"input": times, "output": values}]}]
    path = b.save(folder / "a.gltf")
    if edit is not None:
        doc = json.loads(path.read_text())
        edit(doc)
        path.write_text(json.dumps(doc))
    (folder / "s.yaml").write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nimports: [{file: a.gltf}]\nlights: [{type: constant, radiance: 1}]\nrender: {resolution: [16, 16], spp: 1}\n")
    return folder / "s.yaml"


def _external(name: str, field: str) -> Any:
    """An edit that moves the glTF's buffer (field 'buffers') or adds an image file (field 'images') out to `name`."""
    def edit(doc: dict[str, Any]) -> None:
        if field == "buffers":
            doc["buffers"][0]["uri"] = name
        else:
            doc["images"] = [{"uri": name}]
            doc["textures"] = [{"source": 0}]
            doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
            doc["meshes"][0]["primitives"][0]["material"] = 0
    return edit


def _sparse(path: Path, head: bytes, size: int) -> None:
    """A file that claims `size` bytes (sparse: no real gigabytes)."""
    with open(path, "wb") as f:
        f.write(head)
        f.truncate(size)


def _validate_refused(scene: Path, *fragments: str, timeout: float = 60) -> str:
    res = motion("validate", scene, timeout=timeout)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert all(f in lines[0] for f in fragments), lines[0]
    return lines[0]


def test_a_gltf_texture_of_30000_squared_is_a_located_error(tmp_path: Path) -> None:
    (tmp_path / "e").mkdir()
    _validate_refused(_gltf(tmp_path / "e", texture=_png_header(30000, 30000)), "a.gltf: images[0]", "over the limit")  # before: DecompressionBombError traceback
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "big.png").write_bytes(_png_header(30000, 30000))
    _validate_refused(_gltf(tmp_path / "x", edit=_external("big.png", "images")), "a.gltf: images[0] 'big.png'", "over the limit")


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_gltf_buffers_and_images_over_their_bounds_are_refused_unread(tmp_path: Path) -> None:
    huge = 5 << 30
    (tmp_path / "claim").mkdir()
    _validate_refused(_gltf(tmp_path / "claim", edit=lambda d: d["buffers"][0].__setitem__("byteLength", huge)), "buffers[0]", "byteLength 5368709120")
    (tmp_path / "buf").mkdir()
    scene = _gltf(tmp_path / "buf")
    import base64

    doc = json.loads((tmp_path / "buf" / "a.gltf").read_text())
    _sparse(tmp_path / "buf" / "huge.bin", base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]), huge)
    doc["buffers"][0]["uri"] = "huge.bin"
    (tmp_path / "buf" / "a.gltf").write_text(json.dumps(doc))
    _validate_refused(scene, "buffers[0] 'huge.bin'", "5368709120 bytes")  # before: MemoryError
    (tmp_path / "img").mkdir()
    _sparse(tmp_path / "img" / "huge.png", _png_header(4, 4), huge)
    _validate_refused(_gltf(tmp_path / "img", edit=_external("huge.png", "images")), "images[0] 'huge.png'", "5368709120 bytes")
    (tmp_path / "fifo").mkdir()
    os.mkfifo(tmp_path / "fifo" / "pipe.bin")
    _validate_refused(_gltf(tmp_path / "fifo", edit=_external("pipe.bin", "buffers")), "buffers[0] 'pipe.bin'", "not a regular file")  # before: hung


def test_gltf_animation_keys_are_bounded(tmp_path: Path) -> None:
    from motion.pipeline.limits import MAX_GLTF_KEYS

    t0 = time.monotonic()
    _validate_refused(_gltf(tmp_path, keys=MAX_GLTF_KEYS + 1), "animations[0].samplers[0].input", f"the limit is {MAX_GLTF_KEYS}")
    assert time.monotonic() - t0 < 30  # before: every key a record (3 million: minutes and gigabytes)


def test_usd_points_with_99999_time_samples_are_refused_in_seconds(tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    samples = "\n".join(f"        {i}: [(0, 0, 0), (1, {i % 7}, 0), (0, 1, 0)]," for i in range(99_999))
    (tmp_path / "a.usda").write_text(f'#usda 1.0\n(\n    metersPerUnit = 1\n    upAxis = "Y"\n)\ndef Mesh "tri"\n{{\n    int[] faceVertexCounts = [3]\n'
                                     f"    int[] faceVertexIndices = [0, 1, 2]\n    point3f[] points.timeSamples = {{\n{samples}\n    }}\n}}\n")
    (tmp_path / "s.yaml").write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nimports: [{file: a.usda}]\nlights: [{type: constant, radiance: 1}]\nrender: {resolution: [16, 16], spp: 1}\n")
    t0 = time.monotonic()
    _validate_refused(tmp_path / "s.yaml", "a.usda: /tri.points", "99999 time samples of deforming points")  # before: hours (a cache file each, the cache listed per file)
    assert time.monotonic() - t0 < 30


def _npz_of(tmp_path: Path, frames: int) -> tuple[Path, Path]:
    """A real bake of a one-ball shot repeated to `frames` frames (compressed: a few MB), and the scene."""
    import numpy as np

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("last: 1", f"last: {max(frames - 1, 1)}"))
    small = tmp_path / "small.npz"
    assert motion("-q", "bake", scene, "-o", small, "--frames", "0-1").returncode == 0
    with np.load(small) as z:
        arrays = {k: (z[k] if k == "meta" else np.arange(frames, dtype=np.int64) if k == "frames" else np.repeat(z[k][:1], frames, axis=0)) for k in z.files}
    path = tmp_path / "m.npz"
    np.savez_compressed(path, **arrays)
    return path, scene


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_an_npz_of_a_million_frames_renders_the_two_asked_for(tmp_path: Path) -> None:
    path, scene = _npz_of(tmp_path, 1_000_000)
    t0 = time.monotonic()
    res = motion("render", scene, "--motion", path, "--frames", "0-1", "-o", tmp_path / "out", timeout=120)
    assert res.returncode == 0, res.stderr  # before: a record per frame (100,000 frames: 33 s, 2 GB; a million: out of memory)
    assert len(frames_in(tmp_path / "out")) == 2 and time.monotonic() - t0 < 60


def test_an_npz_of_more_frames_than_any_timeline_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.bake import files
    from motion.pipeline.errors import BakeFileError

    path, _ = _npz_of(tmp_path, 5)
    assert [f.frame for f in files.read_baked(path, frames=[3]).frames] == [3]
    monkeypatch.setattr(files, "MAX_BAKE_FRAMES", 4)
    with pytest.raises(BakeFileError, match="5 frames; the limit is 4"):
        files.read_baked(path, frames=[3])


# --- 4. a damaged render-report.json ----------------------------------------------------------

DAMAGED_REPORTS = {
    "wrong-types": json.dumps({"scene_name": "s", "run_id": "r", "frames": [{"frame": [1], "status": "rendered"}], "history": 5}),
    "row-field-wrong-type": json.dumps({"scene_name": "s", "run_id": "r", "frames": [{"frame": 0, "status": "rendered", "render_s": {"x": 1}}]}),
    "not-an-object": "[1, 2, 3]",
    "deep-nesting": '{"scene_name": "s", "history": [' + "[" * 100_000 + "]" * 100_000 + "]}",
    "nested-history": json.dumps({"scene_name": "s", "history": [{"totals": {"a": [[[]]]}}]}),
    "not-utf8": "\udcff",
    "fifo": None,
}


@pytest.mark.parametrize("case", sorted(DAMAGED_REPORTS))
def test_a_damaged_report_is_discarded_with_one_warning_and_rebuilt(tmp_path: Path, case: str) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE)
    out = tmp_path / "out"
    out.mkdir()
    body = DAMAGED_REPORTS[case]
    if body is None:
        os.mkfifo(out / "render-report.json")
    else:
        (out / "render-report.json").write_bytes(body.encode("utf-8", "surrogateescape"))
    res = motion("render", scene, "-o", out, timeout=120)  # before: a traceback after every frame (a FIFO: hung)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    warnings = [line for line in res.stderr.splitlines() if "render-report.json" in line and "warning" in line]
    assert len(warnings) == 1 and "a new report is written" in warnings[0], res.stderr
    rep = report(out)
    assert rep["totals"]["rendered"] == 2 and rep["history"] == [] and rep["folder"]["count"] == 2


def test_the_run_lock_is_never_written_through_a_link_out_of_the_output_folder(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE + "output: {filename: 'sub/{name}.####.exr'}\n")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / claims.CLAIM_DIR).symlink_to(tmp_path / "elsewhere")
    res = motion("render", scene, "-o", tmp_path / "out")
    assert res.returncode == 2 and "outside the output folder" in res.stderr, res.stderr
    assert not os.listdir(tmp_path / "elsewhere") and not frames_in(tmp_path / "out" / "sub")


def _under_2_gib() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, resource.RLIM_INFINITY))


def test_a_frame_whose_pass_cannot_fit_the_address_space_is_refused_before_the_bake(tmp_path: Path) -> None:
    from farm_util import MOTION

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("[16, 12]", "[4096, 4096]"))
    t0 = time.monotonic()
    res = subprocess.run([MOTION, "render", str(scene), "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, preexec_fn=_under_2_gib)
    assert res.returncode == 2 and "s.yaml:4:" in res.stderr and "render.resolution: 4096x4096 needs about 2.3 GB for a worker (8388608 sample lanes a pass" in res.stderr, res.stderr
    assert time.monotonic() - t0 < 30 and not (tmp_path / "out").exists()  # before: std::bad_alloc on 3 attempts after the bake, exit 3
    scene.write_text(BASE.replace("[16, 12]", "[64, 48]"))  # a frame that fits renders under the same limit
    res = subprocess.run([MOTION, "render", str(scene), "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, preexec_fn=_under_2_gib)
    assert res.returncode == 0, res.stderr
