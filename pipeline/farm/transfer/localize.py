"""The parsed scene as a worker renders a shipped job: its files checked out of the store
and linked under their scene-relative names in one folder per manifest, which becomes the
scene's folder (the scene is not parsed again)."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterable, Sequence

from ...errors import AssetError
from ...write_policy import confined
from ...limits import env_size
from ...scene.loader import LoadedScene
from .manifest import ShippedAsset, manifest_key
from .store import check_out, shipped_cache_dir


def checkout_folder(assets: Iterable[ShippedAsset], folder: Path | None = None) -> Path:
    """Where a job's checkout lives on this worker: one folder per manifest (the same
    assets by the same names share it across jobs), beside the cached entries."""
    return (folder if folder is not None else shipped_cache_dir()) / "checkouts" / manifest_key(assets)


def localize(loaded: LoadedScene, assets: Sequence[ShippedAsset], fetch: Callable[[str], bytes], folder: Path | None = None) -> LoadedScene:
    """The parsed scene as this worker renders it: every asset checked out of the cache
    (`check_out`) and linked under its scene-relative name in a checkout folder, which
    becomes the scene's folder, so each path the scene names resolves to the cached copy.
    The scene is not parsed again. A job whose assets alone exceed $MOTION_ASSET_CACHE_CAP
    raises AssetError (the cap would evict a file the job is about to read)."""
    cap = env_size("MOTION_ASSET_CACHE_CAP")
    total = sum(a.size for a in assets)
    if total > cap:
        raise AssetError(f"{loaded.path}: the scene's {len(assets)} files take {total} bytes, more than MOTION_ASSET_CACHE_CAP={cap} on this worker; raise it")
    root = folder if folder is not None else shipped_cache_dir()
    paths = check_out(assets, fetch, root)
    home = checkout_folder(assets, root)
    for rel, target in paths.items():
        link = home / rel
        if not confined(home, link):
            raise AssetError(f"{loaded.path}: {rel} lies outside the scene's folder; a shipped job uses only files inside it")
        if link.is_symlink() and link.resolve() == target.resolve():
            continue
        link.parent.mkdir(parents=True, exist_ok=True)
        tmp = link.with_name(f".{link.name}.{os.getpid()}.link")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(target.resolve())
        os.replace(tmp, link)  # another process checking out the same manifest sees one link or the other
    return replace(loaded, path=home / loaded.path.name)
