"""Converted-asset cache on disk: content-addressed, shared by every worker on a machine.

A mesh is converted once to Mitsuba's fast binary PLY, keyed by a hash of the source bytes
and the conversion settings; written to a temporary name and renamed, so concurrent
workers either see a whole file or none (the loser of a race just renames over an
identical file). The cache has a size cap; the oldest entries (by access time) go first.
"""

from __future__ import annotations

import hashlib
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..cache import cache_root
from ..files import writing
from ..limits import env_size

CONVERSION_VERSION = "ply-v1"

_stats_lock = threading.Lock()
STATS = {"hits": 0, "misses": 0}


def assets_dir() -> Path:
    """The converted-asset folder (under the cache root)."""
    return cache_root() / "assets"


def _digest(path: Path, settings: str) -> str:
    h = hashlib.sha256()
    h.update(settings.encode())
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:32]


def mesh_file(source: Path) -> Path:
    """The cached PLY for a mesh source (.obj or .ply), converting it on first use."""
    source = Path(source)

    def write(tmp: str) -> None:
        import mitsuba as mi

        kind = "ply" if source.suffix.lower() == ".ply" else "obj"
        mi.load_dict({"type": kind, "filename": str(source)}).write_ply(tmp)

    return _converted(source, f"{CONVERSION_VERSION}|{source.suffix.lower()}", ".ply", write)


def alpha_texture(source: Path, raw: bool) -> Path:
    """The cached float EXR of GGX alpha = roughness^2 for a roughness texture (grey; an
    RGB image by its luminance; sRGB-decoded unless `raw`), made on first use: Mitsuba's
    rough plugins take alpha, our files perceptual roughness."""
    source = Path(source)

    def write(tmp: str) -> None:
        import mitsuba as mi
        import numpy as np

        image = mi.Bitmap(str(source))
        # raw: the stored values as they are (keep the file's own gamma flag); else decode sRGB
        bitmap = image.convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.Float32, image.srgb_gamma() if raw else False)
        rough = np.clip(np.array(bitmap, dtype=np.float32), 0.0, 1.0)
        mi.Bitmap(np.maximum(rough**2, 1e-4)).write(tmp)

    return _converted(source, f"alpha-v2|{raw}", ".exr", write)


def _reads_back(tmp: Path) -> bool:
    """A converted asset is published only once it reads back: a PLY as a whole mesh, any
    other file non-empty (Mitsuba's PLY writer leaves an empty file on a full disk, silently)."""
    if tmp.stat().st_size == 0:
        return False
    if tmp.suffix.lower() == ".ply":
        from ..errors import AssetError
        from ..meshes import load_mesh

        try:
            load_mesh(tmp)
        except AssetError:
            return False
    return True


def _converted(source: Path, settings: str, suffix: str, write: Callable[[str], None]) -> Path:
    """The cache file for (`source`'s bytes, `settings`): `write(tmp)` makes it on a miss,
    then it is renamed into place (concurrent writers: the last rename wins, alike)."""
    key = _digest(source, settings)
    target = assets_dir() / f"{source.stem}-{key}{suffix}"
    if target.is_file() and target.stat().st_size > 0:  # (an empty entry is a write a full disk lost: made again)
        with _stats_lock:
            STATS["hits"] += 1
        os.utime(target)  # recently used: the cap evicts least recently used first
        return target
    with _stats_lock:
        STATS["misses"] += 1
    with writing(target, "writing the converted asset", suffix=suffix, verify=_reads_back) as tmp:  # a full cache disk: one line, and no partial entry
        write(str(tmp))
    enforce_cap(keep=target)
    return target


@dataclass(frozen=True)
class CacheInfo:
    """What the asset cache holds: its folder, file count and total size."""

    folder: Path
    files: int
    bytes: int


def info(folder: Path | None = None) -> CacheInfo:
    """The size of the asset cache (or of `folder`)."""
    folder = folder or assets_dir()
    files = [p for p in folder.rglob("*") if p.is_file()] if folder.is_dir() else []
    return CacheInfo(folder, len(files), sum(p.stat().st_size for p in files))


def enforce_cap(cap_bytes: int | None = None, keep: Path | None = None) -> int:
    """Delete least recently used assets until the folder is under the cap (never `keep`);
    returns bytes freed."""
    from ..cache import enforce_cap as cap_folder

    return cap_folder(assets_dir(), cap_bytes if cap_bytes is not None else env_size("MOTION_ASSET_CACHE_CAP"), keep)


def clear(folder: Path) -> int:
    """Remove every file under `folder`; returns the number removed."""
    n = 0
    if folder.is_dir():
        for p in sorted(folder.rglob("*"), reverse=True):
            if p.is_file():
                p.unlink(missing_ok=True)
                n += 1
            elif p.is_dir():
                try:
                    p.rmdir()
                except OSError:
                    pass
    return n
