"""Where motion keeps its on-disk caches (converted assets, imports, kernels, the variant
probe): one root, shared by every stage that caches."""

from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

_DIGESTS: dict[tuple[str, int, int], str] = {}
_RECORDERS: list[dict[str, str]] = []  # open `digests_recorded` blocks, innermost last


def cache_root() -> Path:
    """Root of motion's on-disk caches: $MOTION_CACHE_DIR, else $XDG_CACHE_HOME/motion."""
    env = os.environ.get("MOTION_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "motion"


def check_cache_root() -> None:
    """Before any work: the cache root is a folder or can be made one (a `MOTION_CACHE_DIR`
    that names a file, or a folder we may not write, is one line, not a failure in every
    worker's first frame). UsageError naming it."""
    from .errors import UsageError

    root = cache_root()
    if root.exists() and not root.is_dir():
        raise UsageError(f"the cache folder {root} ($MOTION_CACHE_DIR or $XDG_CACHE_HOME/motion) is a file; point MOTION_CACHE_DIR at a folder")
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"the cache folder {root} cannot be made: {exc.strerror} (set MOTION_CACHE_DIR to a writable folder)") from None
    if not os.access(root, os.W_OK | os.X_OK):
        raise UsageError(f"the cache folder {root} is not writable (set MOTION_CACHE_DIR to a writable folder)")


def enforce_cap(folder: Path, cap_bytes: int, keep: Path | None = None) -> int:
    """Delete the least recently used files of a cache folder until it holds at most
    `cap_bytes` ($MOTION_ASSET_CACHE_CAP, for converted assets and imports alike); returns
    the bytes freed. Temporary files (named .*) are left to their writers, and `keep` (the
    entry just made, about to be used) stays whatever the cap."""
    if not folder.is_dir():
        return 0
    entries = []
    for p in folder.iterdir():
        try:
            st = p.stat()
        except OSError:
            continue
        if p.is_file() and not p.name.startswith("."):
            entries.append((st.st_atime, st.st_size, p))
    entries.sort()
    total = sum(size for _, size, _ in entries)
    entries = [e for e in entries if e[2] != keep]
    freed = 0
    for _, size, path in entries:
        if total - freed <= cap_bytes:
            break
        path.unlink(missing_ok=True)
        freed += size
    return freed


def validation_dir() -> Path:
    """What validation keeps: the scene's compiled validator (scene/compiled.py) and the
    assets whose bytes passed their checks (checked.py), under the cache root."""
    return cache_root() / "validation"


def kernels_dir() -> Path:
    """drjit's kernel cache: $DRJIT_CACHE_DIR, else kernels/ under the cache root."""
    return Path(os.environ.get("DRJIT_CACHE_DIR", str(cache_root() / "kernels")))


def kernel_cache_key() -> str:
    """`motion-kernels-<16 hex>`: what compiled kernels depend on besides the scene (the
    Mitsuba, drjit and motion versions, Python's, the machine and the CPU's model and
    features, the libLLVM in use), for a CI system's cache key. Reads versions from the
    installed packages' metadata: nothing is imported."""
    import hashlib
    import platform
    from importlib.metadata import PackageNotFoundError, version

    parts = [platform.python_version(), platform.machine(), os.environ.get("DRJIT_LIBLLVM_PATH", "")]
    for dist in ("mitsuba", "drjit", "motion-farm"):
        try:
            parts.append(f"{dist}={version(dist)}")
        except PackageNotFoundError:
            parts.append(f"{dist}=?")
    try:
        cpu = Path("/proc/cpuinfo").read_text()
        model = next((line for line in cpu.splitlines() if line.startswith("model name")), "")
        flags = next((line for line in cpu.splitlines() if line.startswith("flags")), "")
        parts += [model, flags]
    except OSError:
        parts.append(platform.processor())
    return "motion-kernels-" + hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]


def file_digest(path: Path) -> str:
    """sha256 of a file's bytes (memoised per path, size and modification time): the key of
    every content-addressed cache (imports, validation, shipped assets) and of the settings hash."""
    st = path.stat()
    memo = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if memo not in _DIGESTS:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _DIGESTS[memo] = h.hexdigest()
    for seen in _RECORDERS:
        seen[memo[0]] = _DIGESTS[memo]
    return _DIGESTS[memo]


@contextmanager
def digests_recorded() -> Iterator[dict[str, str]]:
    """Every file `file_digest` reads inside the block, by resolved path, with its digest:
    the inputs of a reader whose output is kept (a USD stage's layers and the textures it
    converts; a glTF file's buffers and images: imports/memo.py)."""
    seen: dict[str, str] = {}
    _RECORDERS.append(seen)
    try:
        yield seen
    finally:
        del _RECORDERS[next(i for i, r in enumerate(_RECORDERS) if r is seen)]
