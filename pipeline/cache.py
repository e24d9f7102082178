"""Where motion keeps its on-disk caches, and the one cache layer they all go through.

One root (`cache_root`) holds every cache, shared by the workers of a machine. Each cache
motion keeps there is a `Store` in `STORES` (converted assets, converted imports, import
records, kept asset passes, kept validators, shipped files): a content store with one key
and code-version rule (`Store.key`), one whole-file check and trust rule (`Store.hit`:
only a regular file we wrote, in folders only we may write, is believed), bounded reads
(`Store.read`), stats, and one eviction policy (`hold_to_cap`: least recently used first,
to a byte or entry cap). Nothing read from a store is executed, except a kept validator
(scene/compiled.py), which is read only through `trusted`. The content digests that key
the stores' entries are scene/files.py's (`file_digest`, `snapshot`). docs/ci-sharding.md
("Caches")."""

from __future__ import annotations

import hashlib
import os
import re
import stat
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

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
    if not trusted_folder(root) and str(root) not in _WARNED:
        import logging

        _WARNED.add(str(root))
        logging.getLogger("motion").warning(f"motion: warning: the cache folder {root} is not ours alone (another user may write it): nothing kept there is used, everything is made again")


_WARNED: set[str] = set()  # cache roots warned about in this process


def validation_dir() -> Path:
    """What validation keeps: the scene's compiled validator (scene/compiled.py), the scene
    files parsed (source.py: parse_kept) and the assets whose bytes passed their checks
    (checked.py), under the cache root."""
    return cache_root() / "validation"


def kernels_dir() -> Path:
    """drjit's kernel cache: $DRJIT_CACHE_DIR, else kernels/ under the cache root."""
    return Path(os.environ.get("DRJIT_CACHE_DIR", str(cache_root() / "kernels")))


# What drjit writes in its kernel cache folder (drjit-core's io.cpp): one file a kernel,
# `<32 hex digits>.<backend>.v<format>.bin` (`0ab0...e8.llvm.v6.bin`; `<hex>.<backend>.bin`
# before drjit 1.1), its writer's temporary `<that name>.<number>.tmp` (`<that name>.tmp`
# before), and the `sweep.stamp` of its size sweep. Nothing else there is drjit's or ours:
# $DRJIT_CACHE_DIR may name a folder others keep files in.
_KERNEL_FILE = re.compile(r"[0-9a-f]{32}\.[a-z0-9_]+(\.v[0-9]+)?\.bin(\.[0-9]+)?(\.tmp)?|sweep\.stamp")


def is_kernel_file(name: str) -> bool:
    """Whether a file name in the kernel cache folder is one drjit writes there
    (`_KERNEL_FILE`): a kernel, a kernel being written, the sweep stamp."""
    return _KERNEL_FILE.fullmatch(name) is not None


def kernel_files(folder: Path | None = None) -> list[Path]:
    """drjit's files in the kernel cache folder (`folder`, default `kernels_dir()`): regular
    files named as drjit names them, at its top level only (a subfolder, a link, or any
    other file is someone else's). Empty when the folder is missing or unreadable."""
    folder = kernels_dir() if folder is None else folder
    try:
        with os.scandir(folder) as entries:
            return [Path(e.path) for e in entries if is_kernel_file(e.name) and e.is_file(follow_symlinks=False)]
    except OSError:
        return []


def clear_kernels(folder: Path | None = None) -> int:
    """Remove drjit's files from the kernel cache folder (`kernel_files`), never another
    file there; returns how many went."""
    n = 0
    for path in kernel_files(folder):
        try:
            path.unlink()
            n += 1
        except FileNotFoundError:
            pass  # another process's sweep or writer took it
    return n


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


# --- the one cache layer ------------------------------------------------------------------------
# Every cache motion keeps under the root is a `Store` (one record in STORES): where its entries
# live, what version of code they depend on, how they are evicted. The store does what every
# cache needs once: an entry is used only if it is ours (`trusted`), whole (the caller's check)
# and read bounded (never a FIFO); a miss is made under a temporary name and renamed; then the
# entry's folder is held to its cap (least recently used first; a hit is a use).

_TRUSTED_FOLDERS: set[tuple[str, int, int]] = set()  # (folder, device, inode) found ours this process
_SOURCE = Path(__file__).resolve().parent  # pipeline/: a store's `code` is named relative to it


def _ours(st: os.stat_result, folder: bool) -> bool:
    """Owned by this process's user and writable by nobody else (a folder that others may
    write but not rename in, sticky like /tmp, is enough for the root)."""
    if st.st_uid != os.geteuid():
        return False
    return not st.st_mode & 0o022 or (folder and bool(st.st_mode & stat.S_ISVTX))


def trusted_folder(folder: Path, root: Path | None = None) -> bool:
    """Whether `folder` and every folder from the cache root down to it are ours and
    writable by nobody else: only then may an entry in it be believed (another user who can
    write there could plant one). Links below the root are refused; the root may be one. A
    folder outside the cache root (a caller's own) is judged by itself."""
    root = root if root is not None else cache_root()
    try:
        rel = Path(folder).relative_to(root)
    except ValueError:
        root, rel = Path(folder), Path()
    path = root
    for i, part in enumerate(("",) + rel.parts):
        path = path / part if part else path
        try:
            st = os.stat(path) if i == 0 else os.lstat(path)
        except OSError:
            return False
        memo = (str(path), st.st_dev, st.st_ino)
        if memo in _TRUSTED_FOLDERS:
            continue
        if not stat.S_ISDIR(st.st_mode) or not _ours(st, folder=i == 0):
            return False
        _TRUSTED_FOLDERS.add(memo)
    return True


def trusted(path: Path) -> os.stat_result | None:
    """The entry's stat if it is a regular file we wrote (ours, writable by nobody else, no
    link) in a trusted folder (`trusted_folder`); else None: missing, planted, or reachable
    by another user."""
    try:
        st = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode) or not _ours(st, folder=False) or not trusted_folder(Path(path).parent):
        return None
    return st


def file_stamp(path: str | Path) -> str:
    """'path:size:mtime_ns' ('path:absent' when it cannot be read): what Python checks before
    it reuses a module's bytecode, so a file that would run differently stamps differently."""
    try:
        st = os.stat(path)
    except OSError:
        return f"{path}:absent"
    return f"{path}:{st.st_size}:{st.st_mtime_ns}"


def package_file(name: str) -> Path | None:
    """The file an installed package is imported from (its `__init__.py`), located and not
    imported; None when it is not installed. Its `file_stamp` names the installed build
    without importlib.metadata (whose email parser costs 30 ms of a process)."""
    import importlib.util

    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    return Path(spec.origin) if spec is not None and spec.origin else None


def package_stamps(name: str) -> list[str]:
    """The `file_stamp` of each file at the top of an installed package's folder (its
    modules and the shared libraries beside them), located and not imported: what names
    its installed build; ['NAME:absent'] when it is not installed."""
    path = package_file(name)
    if path is None:
        return [f"{name}:absent"]
    folder = path.resolve().parent
    try:
        return sorted(file_stamp(folder / e.name) for e in os.scandir(folder) if e.is_file())
    except OSError:
        return [f"{name}:unreadable"]


def code_digest(files: Sequence[str]) -> str:
    """The SHA-256 of source files (named relative to pipeline/): the one code version a
    store's entries are stamped with."""
    h = hashlib.sha256()
    for name in files:
        h.update(name.encode() + b"\0" + (_SOURCE / name).read_bytes())
    return h.hexdigest()


@dataclass
class Store:
    """One on-disk cache under the cache root: `folder` (relative to the root), what it
    holds (`what`, for `motion cache info`), the version its entries are keyed with (`tag`,
    plus the digest of the `code` files that make them), and its cap: `cap_bytes` holds each
    of its folders to $MOTION_ASSET_CACHE_CAP bytes, `cap_files` to that many entries;
    `shards` spreads entries over 256 folders by their key's first two digits."""

    name: str
    folder: str
    what: str
    tag: str = ""
    code: tuple[str, ...] = ()
    cap_bytes: bool = True
    cap_files: int | None = None
    shards: bool = False
    stats: dict[str, int] = field(default_factory=lambda: {"hits": 0, "misses": 0, "refused": 0})
    _version: str | None = field(default=None, repr=False)

    def dir(self) -> Path:
        """The store's folder."""
        return cache_root() / self.folder

    def version(self) -> str:
        """The code version every key includes: `tag`, then the digest of `code` (read once
        a process)."""
        if self._version is None:
            self._version = self.tag + (":" + code_digest(self.code) if self.code else "")
        return self._version

    def key(self, *parts: str, length: int = 32) -> str:
        """The hex key of an entry made from `parts` (content digests, settings) by this
        version of the code."""
        return hashlib.sha256("|".join((self.version(),) + parts).encode()).hexdigest()[:length]

    def path(self, key: str, stem: str = "", suffix: str = "") -> Path:
        """Where the entry of `key` lives (`stem-key.suffix`; in its shard when sharded)."""
        folder = self.dir() / key[:2] if self.shards else self.dir()
        return folder / (f"{stem}-{key}{suffix}" if stem else f"{key}{suffix}")

    def hit(self, entry: Path, whole: Callable[[Path], bool] | None = None) -> bool:
        """Whether `entry` is there, ours (`trusted`) and whole (`whole(entry)`, the store's
        check that it reads back); a hit is marked used (the cap evicts others first). An
        entry that is there but not ours or not whole is counted `refused` and made again."""
        st = trusted(entry)
        if st is None or (whole is not None and not whole(entry)):
            with _STATS_LOCK:
                self.stats["misses"] += 1
                if st is not None or os.path.lexists(entry):
                    self.stats["refused"] += 1
            return False
        with _STATS_LOCK:
            self.stats["hits"] += 1
        try:
            os.utime(entry)  # least recently used order, on relatime and noatime mounts too
        except OSError:
            pass
        return True

    def make(self, entry: Path, write: Callable[[Path], None], doing: str, verify: Callable[[Path], bool] | None = None, hold: bool = True) -> Path:
        """Make `entry` by `write(tmp)` under a temporary name beside it, renamed into place
        whole (pipeline/write_policy.py: a full disk is one DiskFaultError line and leaves nothing);
        then its folder is held to the cap (unless `hold` is False: the caller holds it once
        after a run of writes)."""
        from .write_policy import writing

        with writing(entry, doing, suffix=entry.suffix or ".tmp", verify=verify) as tmp:
            write(tmp)
        if hold:
            self.hold(entry.parent, keep=entry)
        return entry

    def get_or_make(self, entry: Path, write: Callable[[Path], None], doing: str, whole: Callable[[Path], bool] | None = None,
                    verify: Callable[[Path], bool] | None = None) -> Path:
        """`entry` when it is a hit, else made by `write(tmp)` (`make`)."""
        if self.hit(entry, whole):
            return entry
        return self.make(entry, write, doing, verify)

    def put(self, entry: Path, data: bytes, best_effort: bool = False, doing: str = "writing a cache entry") -> bool:
        """Keep `data` at `entry`; with `best_effort`, a disk that refuses it is False (its
        loss costs only recomputation), else DiskFaultError."""
        from .errors import DiskFaultError

        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
            self.make(entry, lambda tmp: tmp.write_bytes(data), doing)
        except (OSError, DiskFaultError):
            if not best_effort:
                raise
            return False
        return True

    def read(self, entry: Path, limit: int) -> bytes | None:
        """The bytes of a trusted entry of at most `limit` bytes, else None (missing, not
        ours, not a regular file: a FIFO is never waited on, over the limit)."""
        from .limits import InputFileError, read_bounded

        if trusted(entry) is None:
            if os.path.lexists(entry):
                with _STATS_LOCK:
                    self.stats["refused"] += 1
            return None
        try:
            return read_bounded(entry, limit, "cache entry")
        except InputFileError:
            return None

    def hold(self, folder: Path, keep: Path | None = None) -> int:
        """The one eviction policy: over its cap (bytes or entries), a folder's least
        recently used entries go until it is within it; temporary files (named .*) are left
        to their writers and `keep` (the entry just made) stays. Returns the bytes freed."""
        from .limits import env_size

        cap_bytes = env_size("MOTION_ASSET_CACHE_CAP") if self.cap_bytes else None
        return hold_to_cap(folder, cap_bytes, self.cap_files, keep)

    def entries(self) -> list[Path]:
        """Every entry of the store (its folder's files, and its shards')."""
        root = self.dir()
        folders = [root] + (sorted(p for p in root.iterdir() if p.is_dir() and len(p.name) == 2) if self.shards and root.is_dir() else [])
        out = []
        for folder in folders:
            try:
                out += [Path(e.path) for e in os.scandir(folder) if e.is_file(follow_symlinks=False) and not e.name.startswith(".")]
            except OSError:
                continue
        return out

    def info(self) -> tuple[int, int]:
        """(entries, bytes) the store holds."""
        files = self.entries()
        size = 0
        for p in files:
            try:
                size += p.lstat().st_size
            except OSError:
                pass
        return len(files), size


_STATS_LOCK = threading.Lock()


def hold_to_cap(folder: Path, cap_bytes: int | None, cap_files: int | None = None, keep: Path | None = None) -> int:
    """`Store.hold` for any folder: least recently used entries (by modification time, which
    a hit renews) go until at most `cap_bytes` bytes and `cap_files` entries remain (None:
    no bound); never `keep`, never temporary files (.*). Returns the bytes freed."""
    try:
        found = [(e.stat(follow_symlinks=False), e.path) for e in os.scandir(folder) if e.is_file(follow_symlinks=False) and not e.name.startswith(".")]
    except OSError:
        return 0
    entries = sorted((st.st_mtime_ns, st.st_size, p) for st, p in found)
    total, count = sum(size for _, size, _ in entries), len(entries)
    freed = 0
    for _, size, path in entries:
        if (cap_bytes is None or total - freed <= cap_bytes) and (cap_files is None or count <= cap_files):
            break
        if keep is not None and path == str(keep):
            continue
        try:
            os.unlink(path)
        except OSError:
            continue
        freed += size
        count -= 1
    return freed


# Every cache motion keeps under the root; `motion cache info` lists them. A new cache is one
# entry here and its use through the Store's methods.
STORES: dict[str, Store] = {s.name: s for s in (
    Store("assets", "assets", "meshes and roughness textures converted for Mitsuba (render/translate/assets.py)", tag="ply-v2"),
    Store("imports", "assets/imports", "meshes, textures and skins converted from glTF and USD imports (scene/imports/converted.py)", tag="import-v2"),
    Store("import-records", "assets/imports/records", "the records of glTF and USD imports (scene/imports/memo.py)", tag="records-v3", cap_files=4096),
    Store("passes", "validation/assets", "asset files whose bytes passed their checks (scene/checked.py)", tag="pass-v2",
          code=("images.py", "meshes.py", "limits.py"), cap_bytes=False, cap_files=1024, shards=True),
    Store("parsed", "validation/parsed", "scene files parsed from YAML, as JSON, by their bytes (scene/source.py: parse_kept)", tag="parsed-v1",
          code=("scene/source.py",), cap_files=256),
    Store("validators", "validation", "the scene format's validators (scene/compiled.py)", tag="validator-v2", cap_bytes=False, cap_files=64),
    Store("shipped", "shipped", "assets a shipped job carried to this worker (farm/transfer/store.py)"),
    Store("simulations", "simulations", "dynamics simulations kept for reruns whose dynamics inputs did not change (bake/keep.py)", tag="sim-v1", cap_files=64),
    Store("probes", "probes", "the denoiser probe's answer, by the library's files and this machine (render/output/denoise.py), and the deliverables' "
          "view transform's description, by its options and OpenColorIO's files (shot/deliver.py)", tag="probe-v2", cap_files=64),
    Store("frame-keys", "frame-keys", "each frame's identity and the look, kept for reruns that render nothing (identity/kept.py)", tag="keys-v1", cap_files=256),
)}
