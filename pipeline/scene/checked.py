"""Asset files whose exact bytes passed their check before.

The validation stage opens and decodes every image and mesh a scene names before any task
(`images.check_image`, `meshes.load_mesh`), paid by every `motion validate` and every
render's main process (docs/ci-sharding.md, "What validation keeps", has the figures). A check
is a function of the file's bytes, the reader its suffix picks and the checking code, so its
passing is kept: one empty file in the `passes` store (`cache.STORES`, under the cache
root's `validation/assets/`), named by the SHA-256 of the check's kind, the file's suffix,
the file's bytes and the source of the modules that check. The next check of the same bytes
by the same reader hashes them (the settings hash reads them anyway) and decodes nothing.

What is checked is what was hashed: on a miss the check reads a private copy of the bytes
the pass is then kept under (`cache.snapshot`), so a file swapped between the hash and the
read never leaves a pass for bytes that were not checked. A pass is believed only if we
wrote it (`cache.trusted`: a pass planted by another user who can write the cache root is
no pass). Only a pass is kept: a file that fails is decoded again each time, so its error
is always today's. A file over its kind's size bound is never hashed here; its check refuses
it. Losing the folder costs one decode per file (`motion cache clear --what passes`). The
passes are spread over 256 folders by their names' first two digits, each held to the
store's cap (least recently used first, as every store).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from ..cache import STORES
from .files import file_digest, snapshot

STORE = STORES["passes"]
SHARD_CAP = STORE.cap_files  # passes kept in one of the 256 folders


def _key(kind: str, suffix: str, digest: str) -> Path:
    return STORE.path(STORE.key(kind, suffix.lower(), digest, length=40))


def passed(path: Path, kind: str, most_bytes: int) -> bool:
    """Whether `path`'s present bytes passed the `kind` check before, as read by the reader
    its suffix picks (a kept pass we wrote). False for a file over `most_bytes` (its check
    refuses it) or one that cannot be read (its check says why)."""
    try:
        if path.stat().st_size > most_bytes:
            return False
        return STORE.hit(_key(kind, path.suffix, file_digest(path)))
    except OSError:
        return False


def check(path: Path, kind: str, most_bytes: int, run: Callable[[Path], object]) -> None:
    """Run the `kind` check `run` on a private copy of `path`'s bytes (same name and
    suffix) and, when it passes, keep the pass under the digest of exactly those bytes.
    `run`'s error passes through (naming the copy: callers keep the reason only); a file
    that cannot be copied (not a regular file, over `most_bytes`, unreadable) is checked in
    place, which says why, and nothing is kept."""
    from ..errors import InputFileError

    try:
        with snapshot(path, most_bytes, f"{kind} file") as (digest, copy):
            run(copy)
            remember_pass(_key(kind, path.suffix, digest))
    except InputFileError:
        run(path)


def remember_pass(kept: Path) -> None:
    """Keep a pass at `kept` (best effort: its loss costs one decode)."""
    STORE.put(kept, b"", best_effort=True, doing="keeping an asset's pass")

