"""Converted import assets (meshes as binary PLY, skin weights as .npz, textures as
images) in the content-addressed asset cache: a file's name carries a hash of the source
file's bytes and the conversion settings, so a second load (in any worker on the machine)
finds it and skips the conversion; writes go to a temporary name and are renamed."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from ...cache import STORES

if TYPE_CHECKING:  # numpy and meshes.py are imported where a file is written or checked: a warm import needs neither
    import numpy as np

STORE = STORES["imports"]
CONVERSION_VERSION = STORE.tag  # import-v2: stricter accessor reading (sparse indices); entries made by a laxer reader are not reused
STATS = STORE.stats  # converted-file hits / misses (refused: not ours or not whole); "records": record-set hits (memo.py)
STATS["records"] = 0


def cache_dir() -> Path:
    """Where converted import assets live (beside the renderer's converted meshes)."""
    return STORE.dir()


def converted_file(path: Path) -> bool:
    """Whether `path` is one of the files import expansion made in this machine's cache
    (a converted mesh, an extracted texture, skin arrays), which the expanded scene names by
    an absolute path: a frame header names it by its file name, a shipped job carries it."""
    return Path(path).resolve().is_relative_to(cache_dir().resolve())


def cached(stem: str, key: str, suffix: str, write: Callable[[Path], None], hold_cap: bool = True) -> Path:
    """The cache file for (`key`, conversion version); `write(tmp_path)` makes it on a miss.
    `key` names the bytes the conversion reads (the callers hash what they convert).
    `hold_cap=False`: one of many writes in a row, whose caller holds the cache to its cap
    once after the last (`hold_cap`): each hold lists the whole folder."""
    from ...meshes import cache_entry_whole

    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)[:48]
    target = STORE.path(STORE.key(key), safe, suffix)
    if STORE.hit(target, cache_entry_whole):  # (an entry cut short, emptied or planted is made again, never a hit)
        return target
    write_atomic(target, write, hold_cap)
    return target


def hold_cap(keep: Path | None = None) -> None:
    """The import cache held to $MOTION_ASSET_CACHE_CAP (the oldest entries go; `keep` stays)."""
    STORE.hold(cache_dir(), keep=keep)


def write_atomic(target: Path, write: Callable[[Path], None], cap: bool = True) -> None:
    """`write(tmp)` to a temporary name beside `target`, then rename it into place (the one
    write policy, pipeline/write_policy.py: a concurrent reader sees the whole file or none, a full
    cache disk is one line and leaves no partial entry); then the cache is held to
    $MOTION_ASSET_CACHE_CAP (the store's one eviction policy; unless `cap` is False: the
    caller then holds it once after a run of writes, `hold_cap`)."""
    from ...meshes import cache_entry_whole

    STORE.make(target, write, "writing the import cache", verify=lambda p: cache_entry_whole(p, full=True), hold=cap)


def write_ply(path: Path, positions: np.ndarray, faces: np.ndarray | None, normals: np.ndarray | None = None, uvs: np.ndarray | None = None) -> None:
    """A binary little-endian PLY: float x y z [nx ny nz] [u v] per vertex, triangles as
    `list uchar int`, the layout Mitsuba's PLY loader and pipeline/meshes.py both read."""
    import numpy as np

    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if uvs is not None:
        fields += [("u", "<f4"), ("v", "<f4")]
    verts = np.empty(len(positions), dtype=fields)
    for axis, name in enumerate("xyz"):
        verts[name] = positions[:, axis]
    if normals is not None:
        for axis, name in enumerate(("nx", "ny", "nz")):
            verts[name] = normals[:, axis]
    if uvs is not None:
        verts["u"], verts["v"] = uvs[:, 0], uvs[:, 1]
    tris = np.empty(0 if faces is None else len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    if faces is not None:
        tris["n"], tris["i"] = 3, faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(verts)}"]
    header += [f"property float {name}" for name, _ in fields]
    header += [f"element face {len(tris)}", "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(verts.tobytes())
        f.write(tris.tobytes())
