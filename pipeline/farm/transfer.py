"""Jobs that carry their inputs (docs/farm.md, "A farm without a shared disk"): the client
lists every file the scene names by SHA-256 content hash (refusing, before anything is
read or sent, a file outside the scene's folder); each worker keeps the files it receives in
an on-disk content-addressed cache bounded by $MOTION_ASSET_CACHE_CAP and reused across jobs,
and resolves the scene's relative asset paths to its cached copies. The bytes travel by
Dask's own transfer (`client.scatter`); this module holds the two ends that need no cluster."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

from ..cache import cache_root, enforce_cap
from ..errors import AssetError
from ..files import confined, write_atomic
from ..limits import env_size
from ..scene.checks import named_files
from ..scene.schema import Scene
from ..scene.source import yaml_path


@dataclass(frozen=True)
class ShippedAsset:
    """One file a shipped job carries: its path relative to the scene's folder (as the
    scene names it), its SHA-256 content hash and its size in bytes."""

    rel: str
    sha256: str
    size: int


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def asset_manifest(scene: Scene, base_dir: Path, scene_file: str | Path) -> list[ShippedAsset]:
    """Every file the scene names (`named_files`, the asset checks' own walk), each once, by
    content hash. A path that leads outside the scene's folder (`..`, an absolute path, a
    link) raises AssetError naming the scene file and the YAML path, before any file is read:
    a shipped job never carries the client's other files to the cluster."""
    base = Path(base_dir)
    named = list(named_files(scene))
    for loc, rel, _kind, _deforming in named:
        if not confined(base, base / rel):
            raise AssetError(f"{scene_file}: {yaml_path(loc)}: {rel} lies outside the scene's folder {base.resolve()}; a shipped job sends only files inside it")
    out: dict[str, ShippedAsset] = {}
    for _loc, rel, _kind, _deforming in named:
        if rel not in out:
            path = base / rel
            out[rel] = ShippedAsset(rel, _sha256_file(path), path.stat().st_size)
    return list(out.values())


def shipped_cache_dir() -> Path:
    """The worker's cache of shipped assets (under the cache root), one file per content hash."""
    return cache_root() / "shipped"


def store(sha256: str, data: bytes, folder: Path | None = None) -> Path:
    """Keep `data` in the content-addressed cache as `<folder>/<sha256>` and return its path.
    Bytes that do not hash to `sha256` (damaged in transit) raise AssetError and are not
    kept; a full cache disk raises the one-line DiskFaultError (pipeline/files.py); the cache
    is then held to $MOTION_ASSET_CACHE_CAP, least recently used first, keeping this entry."""
    folder = folder if folder is not None else shipped_cache_dir()
    got = hashlib.sha256(data).hexdigest()
    if got != sha256:
        raise AssetError(f"shipped asset {sha256[:16]}: received {len(data)} bytes hashing to {got[:16]}; expected the file with hash {sha256[:16]}")
    target = folder / sha256
    write_atomic(target, data, "caching a shipped asset")
    enforce_cap(folder, env_size("MOTION_ASSET_CACHE_CAP"), keep=target)
    return target


def cached(asset: ShippedAsset, folder: Path | None = None) -> Path | None:
    """The cached copy of `asset` when this worker already holds it whole (marked as just
    used, so the cap evicts others first), else None."""
    path = (folder if folder is not None else shipped_cache_dir()) / asset.sha256
    try:
        if path.stat().st_size != asset.size:
            return None
        os.utime(path)  # least-recently-used order survives relatime/noatime mounts
    except OSError:
        return None
    return path


def check_out(assets: Iterable[ShippedAsset], fetch: Callable[[str], bytes], folder: Path | None = None) -> dict[str, Path]:
    """Each asset's local path on this worker, by the path the scene names it with: a cached
    copy when there is one, else `fetch(sha256)` (the scattered bytes) stored first. Only
    missing assets are fetched, so a worker receives each file once across jobs."""
    out: dict[str, Path] = {}
    for asset in assets:
        path = cached(asset, folder)
        out[asset.rel] = path if path is not None else store(asset.sha256, fetch(asset.sha256), folder)
    return out
