"""Shipped jobs' two ends without a cluster (pipeline/farm/transfer/): the client's asset
manifest (content hashes, hostile paths refused before reading) and the worker's
content-addressed cache (hash-checked, bounded by $MOTION_ASSET_CACHE_CAP, a full disk is
one line)."""

from __future__ import annotations

import hashlib
import os
import subprocess
from pathlib import Path

import pytest

from motion.pipeline.errors import AssetError, DiskFaultError
from motion.pipeline.farm.transfer.manifest import ShippedAsset, asset_manifest
from motion.pipeline.farm.transfer.store import cached, check_out, store
from motion.pipeline.scene import load_scene

OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _scene(folder: Path, texture: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "tri.obj").write_text(OBJ)
    (folder / "scene.yaml").write_text(
        "timeline: {fps: 24, first: 0, last: 1}\n"
        "camera: {position: [0, 1, 9], look_at: [0, 0, 0]}\n"
        f"materials:\n  - {{name: tex, type: diffuse, color: {{file: {texture}}}}}\n"
        "objects:\n"
        "  - {name: a, shape: mesh, file: tri.obj, material: tex}\n"
        "  - {name: b, shape: mesh, file: tri.obj, material: tex}\n"
    )
    return folder / "scene.yaml"


def test_manifest_hashes_each_named_file_once(tmp_path: Path) -> None:
    path = _scene(tmp_path / "shot", "tex.png")
    (tmp_path / "shot" / "tex.png").write_bytes(b"not decoded here")
    loaded = load_scene(path, assets=False)
    got = {a.rel: a for a in asset_manifest(loaded.scene, loaded.base_dir, path)}
    assert sorted(got) == ["tex.png", "tri.obj"]  # tri.obj named twice, listed once
    assert got["tri.obj"] == ShippedAsset("tri.obj", hashlib.sha256(OBJ.encode()).hexdigest(), len(OBJ))


@pytest.mark.parametrize("hostile", ["../secret.png", "link/secret.png", "alias.png"])
def test_asset_outside_the_scene_folder_is_refused_before_reading(tmp_path: Path, hostile: str) -> None:
    """A path with `..`, through a linked folder, or a file that is itself a link to a file
    outside the scene's folder (docs/farm.md: links out are refused): AssetError, one line."""
    (tmp_path / "secret.png").write_bytes(b"the client's other file")
    path = _scene(tmp_path / "shot", hostile)
    (tmp_path / "shot" / "link").symlink_to(tmp_path)  # a link inside the folder leading out
    (tmp_path / "shot" / "alias.png").symlink_to(tmp_path / "secret.png")  # the asset itself is a link out
    loaded = load_scene(path, assets=False)
    with pytest.raises(AssetError) as exc:
        asset_manifest(loaded.scene, loaded.base_dir, path)
    line = str(exc.value)
    assert "\n" not in line and str(path) in line and "materials[0].color.file" in line and "outside the scene's folder" in line


def test_cache_keeps_by_hash_refuses_damaged_bytes_and_reuses(tmp_path: Path) -> None:
    data = b"x" * 1000
    sha = hashlib.sha256(data).hexdigest()
    asset = ShippedAsset("tex.png", sha, len(data))
    fetched: list[str] = []

    def fetch(h: str) -> bytes:
        fetched.append(h)
        return data

    first = check_out([asset], fetch, tmp_path)
    again = check_out([asset], fetch, tmp_path)
    assert first == again == {"tex.png": tmp_path / f"{sha}.png"} and fetched == [sha]  # sent once, then a hit
    assert (tmp_path / f"{sha}.png").read_bytes() == data
    with pytest.raises(AssetError, match="expected the file with hash"):
        store(hashlib.sha256(b"other").hexdigest(), data, tmp_path / "b")
    assert not (tmp_path / "b").exists() or not any((tmp_path / "b").iterdir())


def test_cache_is_held_to_its_cap_least_recently_used_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOTION_ASSET_CACHE_CAP", "2500")
    blobs = [bytes([i]) * 1000 for i in range(3)]
    assets = [ShippedAsset(f"{i}.bin", hashlib.sha256(b).hexdigest(), len(b)) for i, b in enumerate(blobs)]
    store(assets[0].sha256, blobs[0], tmp_path, "0.bin")
    store(assets[1].sha256, blobs[1], tmp_path, "1.bin")
    entry = tmp_path / f"{assets[1].sha256}.bin"
    old = os.stat(entry).st_atime - 100
    os.utime(entry, (old, old))  # 1 used long ago; 0 used just now
    assert cached(assets[0], tmp_path) is not None
    store(assets[2].sha256, blobs[2], tmp_path, "2.bin")
    assert cached(assets[1], tmp_path) is None and cached(assets[0], tmp_path) is not None and cached(assets[2], tmp_path) is not None


def test_full_cache_disk_is_one_line(tmp_path: Path) -> None:
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)], capture_output=True).returncode != 0:
        pytest.skip("needs root and a tmpfs mount to fill a real disk")
    try:
        data = os.urandom(256 * 1024)
        with pytest.raises(DiskFaultError) as exc:
            store(hashlib.sha256(data).hexdigest(), data, disk)
        line = str(exc.value)
        assert "\n" not in line and "No space left on device" in line and "caching a shipped asset" in line
        assert list(disk.iterdir()) == []  # no partial entry left to be a hit later
    finally:
        subprocess.run(["umount", str(disk)], check=True)


def test_a_shipped_job_renders_the_same_pixels_without_the_scene_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The worker gets the parsed scene and the assets' bytes, not the folder: with the
    scene's folder gone, the frame is bit-identical to the one rendered from the folder."""
    import numpy as np
    from PIL import Image

    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.farm.transfer.shipment import BytesByHash, ShippedScene
    from motion.pipeline.frame_output import read_frame
    from motion.pipeline.render.worker import job as job_mod
    from motion.pipeline.identity import scene_hashes
    from motion.pipeline.render.worker.job import RenderJob, render_frames

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "worker-cache"))
    path = _scene(tmp_path / "shot", "sub/tex.png")
    (tmp_path / "shot" / "sub").mkdir()
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    Image.fromarray(np.stack([checker, checker[::-1], 255 - checker], axis=-1)).save(tmp_path / "shot" / "sub" / "tex.png")
    text = path.read_text().replace("position: [0, 1, 9]", "position: [0.3, 0.3, 2.5], look_at: [0.3, 0.3, 0]").replace(", look_at: [0, 0, 0]}", "}")
    path.write_text(text + "lights: [{type: constant, radiance: 1.0}]\nrender: {resolution: [32, 18], spp: 2, max_depth: 2, seed: 3}\n")
    loaded = load_scene(path)
    inputs = evaluate_frames(loaded, [0])
    hashes = scene_hashes(loaded)
    local = RenderJob(str(path), {}, str(tmp_path / "local"), *hashes, cache=False)
    (a,) = render_frames(local, inputs)
    assets = tuple(asset_manifest(loaded.scene, loaded.base_dir, path))
    source = BytesByHash({x.sha256: (loaded.base_dir / x.rel).read_bytes() for x in assets})
    (tmp_path / "shot").rename(tmp_path / "hidden")  # the worker cannot see the folder now
    job_mod._WORKER.clear()
    shipped = RenderJob(str(path), {}, str(tmp_path / "shipped"), *hashes, shipped=ShippedScene(loaded, assets, source))
    (b,) = render_frames(shipped, inputs)
    assert a.ok and b.ok, (a.error, b.error)
    pa, pb = read_frame(a.path).rgba, read_frame(b.path).rgba
    assert np.array_equal(pa, pb) and float(pa[..., :3].std()) > 0.01  # the texture is really seen


def test_frames_come_home_atomically_and_one_lost_on_the_way_fails(tmp_path: Path) -> None:
    """The client's end of a shipped chunk: a frame whose bytes came is published at its
    planned path; one reported written whose bytes did not come fails (the farm retries it);
    this run's claims are released and no temporary file is left."""
    from motion.pipeline.farm.claims import Claimant, claim_path, try_claim
    from motion.pipeline.farm.task import ChunkResult, TaskContext
    from motion.pipeline.farm.transfer.home import publish_home
    from motion.pipeline.render.worker.job import FrameResult, RenderJob

    out = tmp_path / "out"
    out.mkdir()
    paths = {0: str(out / "s.0000.exr"), 1: str(out / "s.0001.exr")}
    ctx = TaskContext("run-a", paths)
    for p in paths.values():
        assert try_claim(p, Claimant.here("run-a"), 1800)[0]
    job = RenderJob("scene.yaml", {}, str(out), "h", "s")
    sent = ChunkResult(3, "w:1", results=[FrameResult(f, f"/worker/tmp/s.{f:04d}.exr", True, "w:1") for f in (0, 1)], frame_bytes={0: b"the frame's bytes"})
    got = publish_home(ChunkResult(-1, "client"), sent, job, ctx)
    assert Path(paths[0]).read_bytes() == b"the frame's bytes" and got.results[0].ok and got.results[0].path == paths[0]
    assert not got.results[1].ok and "lost on the way back" in (got.results[1].error or "") and not Path(paths[1]).exists()
    assert not got.frame_bytes and not any(claim_path(p).exists() for p in paths.values())
    assert sorted(x.name for x in out.iterdir() if x.name != ".motion-claims") == ["s.0000.exr"]  # no temporary file left



def test_an_imported_scene_ships_its_converted_meshes(tmp_path: Path) -> None:
    """A glTF import's meshes are converted into motion's import cache, which the scene then
    names by an absolute path outside its folder (its textures too); a shipped job carries them as
    `.motion-imports/<name>` inside the folder (before, such a scene was refused as hostile),
    reads them from the cache on the client, and the worker's checkout resolves them."""
    import shutil

    from motion.pipeline.farm.transfer.localize import localize
    from motion.pipeline.farm.transfer.manifest import IMPORTED
    from motion.pipeline.farm.transfer.shipment import BytesByHash, ship_job
    from motion.pipeline.render.worker.job import RenderJob

    root = Path(__file__).resolve().parents[2]
    shot = tmp_path / "shot"
    shutil.copytree(root / "scenes" / "assets", shot / "assets")
    shutil.copy(root / "scenes" / "walker.yaml", shot / "walker.yaml")
    loaded = load_scene(shot / "walker.yaml")
    job = ship_job(RenderJob(str(shot / "walker.yaml"), {}, str(tmp_path / "out"), "h", "s"), loaded, shot / "walker.yaml")
    shipped = job.shipped
    imported = [a for a in shipped.assets if a.rel.startswith(IMPORTED + "/")]
    meshes = {a.rel for a in imported if a.rel.endswith(".ply")}  # and the textures the import extracted
    named = {o.file for o in shipped.loaded.scene.objects if getattr(o, "file", None)}
    assert meshes and meshes <= named and not any(Path(f).is_absolute() for f in named)
    payload = BytesByHash({a.sha256: shipped.fetch(a.sha256) for a in shipped.assets})  # read on the client, hash-checked
    there = localize(shipped.loaded, shipped.assets, payload, tmp_path / "worker-cache")
    for a in imported:
        assert hashlib.sha256((there.base_dir / a.rel).read_bytes()).hexdigest() == a.sha256
