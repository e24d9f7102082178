"""Shipped jobs' two ends without a cluster (pipeline/farm/transfer.py): the client's asset
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
from motion.pipeline.farm.transfer import ShippedAsset, asset_manifest, cached, check_out, store
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


@pytest.mark.parametrize("hostile", ["../secret.png", "link/secret.png"])
def test_asset_outside_the_scene_folder_is_refused_before_reading(tmp_path: Path, hostile: str) -> None:
    (tmp_path / "secret.png").write_bytes(b"the client's other file")
    path = _scene(tmp_path / "shot", hostile)
    (tmp_path / "shot" / "link").symlink_to(tmp_path)  # a link inside the folder leading out
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
    assert first == again == {"tex.png": tmp_path / sha} and fetched == [sha]  # sent once, then a hit
    assert (tmp_path / sha).read_bytes() == data
    with pytest.raises(AssetError, match="expected the file with hash"):
        store(hashlib.sha256(b"other").hexdigest(), data, tmp_path / "b")
    assert not (tmp_path / "b").exists() or not any((tmp_path / "b").iterdir())


def test_cache_is_held_to_its_cap_least_recently_used_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOTION_ASSET_CACHE_CAP", "2500")
    blobs = [bytes([i]) * 1000 for i in range(3)]
    assets = [ShippedAsset(f"{i}.bin", hashlib.sha256(b).hexdigest(), len(b)) for i, b in enumerate(blobs)]
    store(assets[0].sha256, blobs[0], tmp_path)
    store(assets[1].sha256, blobs[1], tmp_path)
    old = os.stat(tmp_path / assets[1].sha256).st_atime - 100
    os.utime(tmp_path / assets[1].sha256, (old, old))  # 1 used long ago; 0 used just now
    assert cached(assets[0], tmp_path) is not None
    store(assets[2].sha256, blobs[2], tmp_path)
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
