"""The one way motion writes a file: through a temporary file in the destination
folder and an atomic rename, so a reader sees the old file or the whole new one; on any
failure the temporary file goes; a disk that refuses the write (full, over quota,
read-only, not ours) is one `DiskFaultError` line naming what was being written and where.
Every writer uses it: frames and the temporal pass (frame_output.write_exr), movies,
telecine sequences and deliverables (`staging` + `publish_path`), reports, claims
(`create_exclusive`), exports, sheets, flipbooks, bake files, the caches.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from .errors import DiskFaultError


def _read_umask() -> int:
    # os.umask can only be read by setting it; do it once, at import, while no other
    # thread of ours is creating files
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


# Errors that mean "this disk will not take our writes" (full, over quota, read-only, not
# ours): a job stops on them at once instead of retrying elsewhere (docs/farm.md).
DISK_FAULT_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG)


def disk_fault_errno(exc: BaseException) -> int | None:
    """The errno of a disk fault, or None. OpenEXR reports write errors as RuntimeError
    with the system's message ('... No space left on device.'), so that is read too."""
    if isinstance(exc, DiskFaultError):
        return getattr(exc, "errno", None) or errno.EIO
    if isinstance(exc, OSError) and exc.errno in DISK_FAULT_ERRNOS:
        return exc.errno
    if isinstance(exc, RuntimeError):
        text = str(exc)
        for code in DISK_FAULT_ERRNOS:
            if os.strerror(code) in text:
                return code
    return None


def disk_fault(exc: BaseException, doing: str, path: str | Path) -> DiskFaultError | None:
    """A DiskFaultError (one line: what failed, where, why) for a disk fault, else None."""
    code = disk_fault_errno(exc)
    if code is None:
        return None
    if isinstance(exc, DiskFaultError):
        return exc
    err = DiskFaultError(f"disk fault: {os.strerror(code)} ({errno.errorcode.get(code, code)}) {doing} {path}")
    err.errno = code  # type: ignore[attr-defined]
    return err


@contextmanager
def disk_faults(doing: str, path: str | Path) -> Iterator[None]:
    """Inside, an exception that is a disk fault becomes the one DiskFaultError line
    (`disk_fault`) naming what was being done and where; any other passes unchanged."""
    try:
        yield
    except BaseException as exc:
        fault = disk_fault(exc, doing, path)
        if fault is not None:
            raise fault from None
        raise


def _unlink_quietly(path: str | Path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass  # gone already, or the disk is read-only now: the next run's cleanup removes it


def write_atomic(path: str | Path, data: bytes, doing: str = "writing") -> Path:
    """Write `data` to `path` through a temporary file in the same folder and a rename:
    a reader sees the old file or the whole new one. On any failure the temporary file is
    removed (no zero-byte or partial file is left); a disk fault raises DiskFaultError."""
    with writing(path, doing) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def publish(tmp: str | Path, path: str | Path) -> None:
    """Move a finished temporary file into place atomically, with the permissions a plain
    `open` would have given it (mkstemp makes 0600 files; outputs are shared on a farm)."""
    os.chmod(tmp, 0o666 & ~_UMASK)
    os.replace(tmp, path)


def publish_path(staged: str | Path, final: str | Path) -> None:
    """Move a staged output into place: a file by an atomic rename, a folder by swapping it
    with the old one (renamed aside first, then removed), so a reader sees the old whole or
    the new whole."""
    staged, final = Path(staged), Path(final)
    if not staged.is_dir():
        os.replace(staged, final)
        return
    old = None
    if final.exists() or final.is_symlink():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        os.replace(final, old)
    os.replace(staged, final)
    if old is not None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink()


@contextmanager
def staging(folder: str | Path, doing: str = "staging in", prefix: str = ".staging-") -> Iterator[Path]:
    """`with staging(folder) as tmp:` build several outputs in a hidden folder inside
    `folder` (same file system: publishing them is a rename), move the finished ones out
    with `publish_path`; the folder and whatever is left in it go on leaving. A disk fault
    on the way becomes DiskFaultError naming `folder`."""
    folder = Path(folder)
    tmp: Path | None = None
    try:
        with disk_faults(doing, folder):
            folder.mkdir(parents=True, exist_ok=True)
            tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=folder))
            yield tmp
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


# errors of os.link on file systems without hard links (some network and FUSE mounts)
_NO_LINKS = (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS)


def create_exclusive(path: str | Path, data: bytes, doing: str = "creating") -> bool:
    """Make `path` hold `data` if no file is there yet; False if one is (whoever made it
    first wins, on one machine or across a farm's shared disk). The data is written whole
    under a temporary name and hard-linked into place, one atomic step, so no reader sees
    a partial file; where the file system has no hard links, an exclusive create and a
    write (a reader may then briefly see it empty). A disk fault raises DiskFaultError."""
    path = Path(path)
    tmp: str | None = None
    try:
        with disk_faults(doing, path):
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.chmod(tmp, 0o666 & ~_UMASK)
            try:
                os.link(tmp, path)
                return True
            except FileExistsError:
                return False
            except OSError as exc:
                if exc.errno not in _NO_LINKS:
                    raise
            try:
                fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
            except FileExistsError:
                return False
            try:
                with os.fdopen(fd, "wb") as fh:
                    fh.write(data)
            except BaseException:
                _unlink_quietly(path)
                raise
            return True
    finally:
        if tmp is not None:
            _unlink_quietly(tmp)


def write_best_effort(path: str | Path, data: bytes) -> bool:
    """`write_atomic` for a file whose loss costs only recomputation (a probe cache, the
    cost history): False instead of an error when the disk refuses it."""
    try:
        write_atomic(path, data)
        return True
    except (OSError, DiskFaultError):
        return False



def lost_write(tmp: str | Path, doing: str, path: str | Path) -> DiskFaultError:
    """The DiskFaultError for a write a library did not report failing but that did not
    read back (Mitsuba's PLY writer and OpenEXR leave a short or empty file on a full disk
    and say nothing): ENOSPC when the file system is full, else EIO."""
    code = errno.EIO
    try:
        st = os.statvfs(os.path.dirname(str(tmp)) or ".")
        if st.f_bavail == 0 or st.f_favail == 0:
            code = errno.ENOSPC
    except OSError:
        pass
    err = DiskFaultError(f"disk fault: {os.strerror(code)} ({errno.errorcode[code]}) {doing} {path} (the written file did not read back whole)")
    err.errno = code  # type: ignore[attr-defined]
    return err


@contextmanager
def writing(path: str | Path, doing: str = "writing", suffix: str = ".tmp", verify: Callable[[Path], bool] | None = None) -> Iterator[Path]:
    """`with writing(path) as tmp:` write the whole file at `tmp` (any library's own
    writer: PIL, matplotlib, numpy); on leaving, it is published at `path` atomically. On
    any failure the temporary file is removed and a disk fault becomes DiskFaultError.
    `verify(tmp)` (when given) must say the file reads back before it is published: a cache
    entry that a full disk left empty would otherwise be a hit in every later run."""
    path = Path(path)
    tmp: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
        os.close(fd)
        yield Path(tmp)
        if verify is not None and not verify(Path(tmp)):
            raise lost_write(tmp, doing, path)
        publish(tmp, path)
        tmp = None
    except BaseException as exc:
        if tmp is not None:
            _unlink_quietly(tmp)
        fault = disk_fault(exc, doing, path)
        if fault is not None:
            raise fault from None
        raise


def confined(folder: str | Path, path: str | Path) -> bool:
    """Whether `path` stays inside `folder` once every link on the way is followed: a
    subfolder (or claims folder) pre-placed in the output folder as a link to elsewhere
    would otherwise carry frames out of it."""
    base = Path(folder).resolve()
    target = Path(path).parent.resolve() / Path(path).name
    return target == base or base in target.parents
