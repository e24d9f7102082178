"""Converted-asset cache on disk: content-addressed, shared by every worker on a machine.

A mesh is converted once to Mitsuba's fast binary PLY, keyed by a hash of the source bytes
and the conversion settings; written to a temporary name and renamed, so concurrent
workers either see a whole file or none (the loser of a race just renames over an
identical file). The store (`cache.STORES["assets"]`) holds the rules every cache shares:
only an entry we wrote is used, the cap evicts least recently used first.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ...cache import STORES
from ...scene.files import file_digest, snapshot
from ...limits import MAX_IMAGE_BYTES, MAX_MESH_BYTES
from ...meshes import cache_entry_whole, load_render_mesh, vertex_normals

STORE = STORES["assets"]
CONVERSION_VERSION = STORE.tag
STATS = STORE.stats  # hits, misses (and entries refused: not ours, or not whole)


def assets_dir() -> Path:
    """The converted-asset folder (under the cache root)."""
    return STORE.dir()


def mesh_file(source: Path) -> Path:
    """The cached PLY for a mesh source (.obj or .ply), converting it on first use. A
    source without normals gets the engine's (`meshes.vertex_normals`, Mitsuba's scheme
    summed in a fixed order) rather than those Mitsuba's reader computed: the same normals
    as the slices of the same mesh deforming, and the same bits on every machine whatever
    its thread count (Mitsuba's own sum is an atomic scatter-add)."""
    source = Path(source)

    def write(src: Path, tmp: str) -> None:
        import mitsuba as mi
        import numpy as np

        kind = "ply" if source.suffix.lower() == ".ply" else "obj"
        mesh = mi.load_dict({"type": kind, "filename": str(src)})
        if mesh.has_vertex_normals() and load_render_mesh(src).normals is None:
            params = mi.traverse(mesh)
            positions = np.array(params["vertex_positions"], dtype=np.float32).reshape(-1, 3)
            faces = np.array(params["faces"], dtype=np.int64).reshape(-1, 3)
            params["vertex_normals"] = mi.Float(vertex_normals(positions, faces).astype(np.float32).ravel())
            params.update()
        mesh.write_ply(tmp)

    return _converted(source, source.suffix.lower(), ".ply", write, MAX_MESH_BYTES)


def alpha_texture(source: Path, raw: bool) -> Path:
    """The cached float EXR of GGX alpha = roughness^2 for a roughness texture (grey; an
    RGB image by its luminance; sRGB-decoded unless `raw`), made on first use: Mitsuba's
    rough plugins take alpha, our files perceptual roughness."""
    source = Path(source)

    def write(src: Path, tmp: str) -> None:
        import mitsuba as mi
        import numpy as np

        image = mi.Bitmap(str(src))
        # raw: the stored values as they are (keep the file's own gamma flag); else decode sRGB
        bitmap = image.convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.Float32, image.srgb_gamma() if raw else False)
        rough = np.clip(np.array(bitmap, dtype=np.float32), 0.0, 1.0)
        mi.Bitmap(np.maximum(rough**2, 1e-4)).write(tmp)

    return _converted(source, f"alpha-v2|{raw}", ".exr", write, MAX_IMAGE_BYTES)


def _converted(source: Path, settings: str, suffix: str, write: Callable[[Path, str], None], limit: int) -> Path:
    """The cache file for (`source`'s bytes, `settings`): on a miss, `write(tmp)` converts a
    private copy of the bytes the key was made from (`cache.snapshot`: a file swapped
    meanwhile is never kept under another file's key), then it is renamed into place
    (concurrent writers: the last rename wins, alike)."""
    target = STORE.path(STORE.key(settings, file_digest(source)), source.stem, suffix)
    if STORE.hit(target, cache_entry_whole):  # (an entry cut short, emptied or planted is made again, never a hit)
        return target
    with snapshot(source, limit, "asset file") as (digest, copy):
        target = STORE.path(STORE.key(settings, digest), source.stem, suffix)
        STORE.make(target, lambda tmp: write(copy, str(tmp)), "writing the converted asset", verify=lambda p: cache_entry_whole(p, full=True))
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
