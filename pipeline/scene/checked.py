"""Asset files whose exact bytes passed their check before (issue 28).

The validation stage opens and decodes every image and mesh a scene names before any task
(`images.check_image`, `meshes.load_mesh`): about 0.015 s for a 300 KB JPEG, seconds for a
shot's textures, paid by every `motion validate` and every render's main process. A check
is a function of the file's bytes and the checking code, so its passing is kept: one
empty file in `validation/assets/` under the cache root, named by the SHA-256 of the file's
bytes, the check's kind and the source of the modules that check. The next check of the
same bytes reads and hashes them (the settings hash reads them anyway) and decodes nothing.

Only a pass is kept: a file that fails is decoded again each time, so its error is always
today's. A file over its kind's size bound is never hashed here; its check refuses it.
Losing the folder costs one decode per file (`motion cache clear --what validation`).
The passes are spread over 256 folders by their names' first two digits, each held to
SHARD_CAP files (its oldest half goes when it is full: about 262,000 passes in all, one
per texture version a machine has seen).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from ..cache import file_digest, validation_dir

FORMAT = 1
_CHECKERS = ("images.py", "meshes.py", "limits.py")  # pipeline/: the modules whose code a verdict depends on
_checker_digest: str | None = None
SHARD_CAP = 1024  # passes kept in one of the 256 folders


def _checkers() -> str:
    """The SHA-256 of the checking modules' source (read once a process)."""
    global _checker_digest
    if _checker_digest is None:
        h = hashlib.sha256(str(FORMAT).encode())
        for name in _CHECKERS:
            h.update((Path(__file__).parents[1] / name).read_bytes())
        _checker_digest = h.hexdigest()
    return _checker_digest


def _entry(path: Path, kind: str) -> Path:
    key = hashlib.sha256(f"{kind}|{file_digest(path)}|{_checkers()}".encode()).hexdigest()[:40]
    return validation_dir() / "assets" / key[:2] / key[2:]


def entry(path: Path, kind: str, most_bytes: int) -> Path | None:
    """Where a pass of the `kind` check on `path`'s present bytes is kept (it is there if
    they passed before), hashed before the check reads them so that a pass is kept for the
    bytes it saw. None for a file over `most_bytes` (its check refuses it) or one that
    cannot be read (its check says why)."""
    try:
        if path.stat().st_size > most_bytes:
            return None
        return _entry(path, kind)
    except OSError:
        return None


def remember_pass(kept: Path) -> None:
    """Keep a pass at `kept` (from `entry`; best effort: its loss costs one decode)."""
    from ..files import write_best_effort

    try:
        kept.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    if write_best_effort(kept, b""):
        hold_to_cap(kept.parent)


def hold_to_cap(folder: Path, cap: int | None = None) -> None:
    """Over `cap` passes (SHARD_CAP) in `folder`: remove the oldest until half remain
    (a removed pass costs one decode of its file; temporary files, named .*, are left)."""
    cap = SHARD_CAP if cap is None else cap
    try:
        entries = sorted((e.stat().st_mtime_ns, e.path) for e in os.scandir(folder) if e.is_file() and not e.name.startswith("."))
    except OSError:
        return
    if len(entries) <= cap:
        return
    for _, old in entries[: len(entries) - cap // 2]:
        try:
            os.unlink(old)
        except OSError:
            pass
