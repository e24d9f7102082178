"""The worker's content-addressed store of shipped files (cache.py's `shipped` store): one
entry per content hash, with the suffix the scene's file had; bytes that do not hash to
their name are refused, an entry is believed only when it is ours and whole, and the store
is held to $MOTION_ASSET_CACHE_CAP, least recently used first."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Sequence

from ...cache import STORES
from ...errors import AssetError
from ...scene.files import bytes_digest
from .manifest import ShippedAsset


STORE = STORES["shipped"]


def shipped_cache_dir() -> Path:
    """The worker's cache of shipped assets (under the cache root), one file per content hash."""
    return STORE.dir()


def _entry(folder: Path, sha256: str, rel: str) -> Path:
    """A cache entry's path: the hash, with the suffix the scene's file had (the mesh and
    image loaders choose their reader by it)."""
    return folder / (sha256 + Path(rel).suffix.lower())


def store(sha256: str, data: bytes, folder: Path | None = None, rel: str = "") -> Path:
    """Keep `data` in the content-addressed cache as `<folder>/<sha256><suffix of rel>` and
    return its path.
    Bytes that do not hash to `sha256` (damaged in transit) raise AssetError and are not
    kept; a full cache disk raises the one-line DiskFaultError (pipeline/write_policy.py); the cache
    is then held to $MOTION_ASSET_CACHE_CAP, least recently used first, keeping this entry."""
    folder = folder if folder is not None else shipped_cache_dir()
    got = bytes_digest(data)
    if got != sha256:
        raise AssetError(f"shipped asset {sha256[:16]}: received {len(data)} bytes hashing to {got[:16]}; expected the file with hash {sha256[:16]}")
    target = _entry(folder, sha256, rel)
    STORE.make(target, lambda tmp: tmp.write_bytes(data), "caching a shipped asset")
    return target


def cached(asset: ShippedAsset, folder: Path | None = None) -> Path | None:
    """The cached copy of `asset` when this worker already holds it whole and it is ours
    (a file another user planted under that hash is not used), marked as just used so the
    cap evicts others first; else None."""
    path = _entry(folder if folder is not None else shipped_cache_dir(), asset.sha256, asset.rel)
    return path if STORE.hit(path, lambda p: p.stat().st_size == asset.size) else None


def check_out(assets: Iterable[ShippedAsset], fetch: Callable[[str], bytes], folder: Path | None = None) -> dict[str, Path]:
    """Each asset's local path on this worker, by the path the scene names it with: a cached
    copy when there is one, else `fetch(sha256)` (the scattered bytes) stored first. Only
    missing assets are fetched, so a worker receives each file once across jobs."""
    out: dict[str, Path] = {}
    for asset in assets:
        path = cached(asset, folder)
        if path is None:
            try:
                data = fetch(asset.sha256)
            except KeyError:
                raise AssetError(f"shipped asset {asset.rel} ({asset.sha256[:16]}): not in this worker's cache and not sent with the chunk") from None
            path = store(asset.sha256, data, folder, asset.rel)
        out[asset.rel] = path
    return out


def missing_assets(assets: Sequence[ShippedAsset], warm: str | None = None) -> list[str]:
    """The hashes of `assets` this worker holds neither in memory nor whole in its cache
    (run on a worker by `client.run` before its first chunk of a job: only those bytes are
    sent to it). `warm`: the job's key (`RenderJob.key`, when its workers may reuse their
    renderer); a worker whose renderer holds that job's scene built needs none of its files
    (it never reads them again), wherever it got them (a shared-disk job of the scene)."""
    from ...render.worker.job import warm_key

    if warm is not None and warm_key() == warm:
        return []
    return sorted({a.sha256 for a in assets if cached(a) is None})
