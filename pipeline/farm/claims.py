"""Frame claims: two renders into one folder never write the same frame twice.

Before a worker renders a frame it creates `<output>/.motion-claims/<frame file>.claim`
holding JSON with its owner: run id, host, pid and time. The claim is written whole to a
temporary file first and then hard-linked to its name (`link` fails if the name exists:
atomic on local file systems and on NFS), so a claim is never seen empty or half-written;
where the file system has no hard links, `O_CREAT | O_EXCL` and a write are used instead
(both are the write policy's `write_policy.create_exclusive`).
While the claim exists no other render touches the frame; the worker removes it once the
frame has been renamed into place (or has failed).

A claim found on disk is
- ours (same run id): a retry of our own chunk after its worker died; taken over;
- stale: empty or unreadable (older than WRITE_GRACE_S, which covers a writer without hard
  links between its create and its write), its pid is gone on this host or no process can
  have it (under 1, over MAX_PID: on any host), or it is older
  than `stale_after_s` (default: the task timeout, which no live task outlives); broken by
  an atomic rename and re-claimed;
- live: the frame is left alone; the farm checks back later and re-queues it only if the
  other render gives up without finishing it.

A disk fault (full, read-only, permission denied) while claiming raises DiskFaultError,
leaving no temporary or empty file of ours; releasing never raises (a claim that cannot be
removed from a read-only disk names a process that will be gone: the next run finds it
stale).
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

from ..errors import InputFileError
from ..write_policy import create_exclusive, disk_faults, write_atomic
from ..limits import read_bounded

CLAIM_DIR = ".motion-claims"
MAX_CLOCK_SKEW_S = 300.0  # seconds a claim may be dated ahead of this machine's clock
WRITE_GRACE_S = 5.0  # an empty claim younger than this may still be being written
# the longest a claim protects its frame whatever the limit asked (a NaN or infinite task
# timeout made `age > limit` false forever: the job waited on a dead host's claim for good)
MAX_STALE_AFTER_S = 7 * 24 * 3600.0
CLAIM_BYTES = 64 * 1024  # a claim is a line of JSON; a bigger file is not one of ours
MAX_PID = 1 << 22  # Linux's PID_MAX_LIMIT: no process on any host of a farm has a larger pid


@dataclass(frozen=True)
class Claimant:
    """Who holds a claim: the run (one `motion render` invocation) and the process."""

    run_id: str
    host: str
    pid: int

    @classmethod
    def here(cls, run_id: str) -> "Claimant":
        """The claimant of this process (its host and pid) for run `run_id`."""
        return cls(run_id=run_id, host=_host(), pid=os.getpid())


def _host() -> str:
    """This machine's name, as `socket.gethostname()` gives it on POSIX (uname's node name),
    without loading the socket module: a rerun that renders nothing takes its run lock."""
    return os.uname().nodename


def new_run_id() -> str:
    """A fresh id for one `motion render` invocation."""
    return f"{_host()}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def claim_path(frame_file: str | Path) -> Path:
    """Where the claim of a frame file lives (in a `.motion-claims/` folder beside it)."""
    frame_file = Path(frame_file)
    return frame_file.parent / CLAIM_DIR / (frame_file.name + ".claim")


def read_claim(path: Path) -> dict | None:
    """The claim's content; {} if empty, unreadable or not a claim (a FIFO is never waited
    on, a file over CLAIM_BYTES is not read); None if it is gone."""
    try:
        text = read_bounded(path, CLAIM_BYTES, "frame claim")
    except InputFileError:
        return None if not os.path.lexists(path) else {}
    try:
        data = json.loads(text)
        return data if isinstance(data, dict) else {}
    except (ValueError, RecursionError):  # not JSON, not UTF-8 (a ValueError), or nested past the decoder's stack
        return {}


def _pid_alive(pid: object) -> bool:
    """Whether `pid` names a live process on this host. A pid no process can have (not an
    integer, under 1, over the kernel's PID_MAX_LIMIT: 2**70) is not alive: its claim or
    lock is stale. (0 and negative numbers would name process groups to os.kill.)"""
    if not isinstance(pid, int) or isinstance(pid, bool) or not 1 <= pid <= MAX_PID:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OSError, OverflowError):
        return False
    return True


def is_stale(path: Path, info: dict, stale_after_s: float) -> bool:
    """A claim that is empty or unreadable (past the write grace), whose process is gone
    (same host), that is older than the limit, or that is dated in the future beyond any
    clock skew between farm machines (MAX_CLOCK_SKEW_S): such a claim would never age, and
    a job waiting on it would wait forever."""
    try:
        age = time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return True
    except OSError:
        return True  # cannot even stat it: it protects nothing
    if age < -MAX_CLOCK_SKEW_S:
        return True
    if not info.get("run_id") or not isinstance(info.get("pid"), int) or isinstance(info.get("pid"), bool):
        return age > WRITE_GRACE_S or age < -WRITE_GRACE_S
    if not 1 <= info["pid"] <= MAX_PID:
        return True  # no process has that pid, on any host
    if info.get("host") == _host():
        if not _pid_alive(info["pid"]):
            return True
    limit = stale_after_s if math.isfinite(stale_after_s) and stale_after_s > 0 else MAX_STALE_AFTER_S
    return age > min(limit, MAX_STALE_AFTER_S)


def try_claim(frame_file: str | Path, who: Claimant, stale_after_s: float) -> tuple[bool, dict | None]:
    """Claim a frame. Returns (True, None) when we hold it, else (False, holder info).
    Raises DiskFaultError when the disk refuses the claim (write_policy.create_exclusive: the
    claim appears whole or not at all)."""
    path = claim_path(frame_file)
    body = json.dumps({**asdict(who), "time": time.time()}).encode()
    with disk_faults("claiming frame", path):
        path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(5):
            if create_exclusive(path, body, "claiming frame"):
                return True, None
            info = read_claim(path)
            if info is None:
                continue  # released between our attempt and our read: try again
            if info.get("run_id") == who.run_id:
                write_atomic(path, body, "claiming frame")  # our own earlier attempt (its worker died): take over
                return True, None
            if is_stale(path, info, stale_after_s):
                _break_stale(path)
                continue
            return False, info
        info = read_claim(path)
        return False, info or {}


def _break_stale(path: Path) -> None:
    """Remove a stale claim atomically: only one breaker's rename succeeds."""
    grave = path.with_name(f"{path.name}.stale.{os.getpid()}.{uuid.uuid4().hex[:6]}")
    try:
        os.rename(path, grave)
        grave.unlink(missing_ok=True)
    except FileNotFoundError:
        pass


def clear_stale(frame_files: list[str], stale_after_s: float) -> int:
    """Remove the stale claims on frames a resumed run keeps as complete: a run stopped
    between publishing a frame and releasing its claim (a disk turned read-only, a kill)
    left one, and no task of a later run claims a complete frame to clear it. A live
    claim is left alone; a disk that refuses the removal too. Returns how many went."""
    n = 0
    for f in frame_files:
        path = claim_path(f)
        info = read_claim(path)
        if info is not None and is_stale(path, info, stale_after_s):
            try:
                _break_stale(path)
                n += 1
            except OSError:
                pass
    return n


def release(frame_file: str | Path, run_id: str) -> bool:
    """Remove our claim on a frame (never someone else's). Never raises: False when the
    claim could not be removed (a read-only disk); it names a process that will be gone,
    so the next run finds it stale."""
    path = claim_path(frame_file)
    info = read_claim(path)
    if info is not None and info.get("run_id") == run_id:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            return False
    return True


def release_all(frame_files: list[str], run_id: str) -> None:
    """Release this run's claims on every frame file given (others' claims are left)."""
    for f in frame_files:
        release(f, run_id)


def remove_partials(frame_file: str | Path) -> int:
    """Delete temporary files a killed writer left for this frame (`.<name>.*.tmp`);
    called only by the holder of the frame's claim. Returns how many were removed."""
    frame_file = Path(frame_file)
    n = 0
    try:
        for p in frame_file.parent.glob(f".{frame_file.name}.*.tmp"):
            p.unlink(missing_ok=True)
            n += 1
    except OSError:
        pass  # gone, or a read-only disk: nothing we can remove now
    return n


# --- the output folder's run locks -------------------------------------------------------
#
# Frame claims keep two renders off one frame; they cannot keep two *versions* of a scene
# (other settings, other motion) out of one folder: each would render the frames the other
# had not reached and both would report success over a mix that `--check` refuses. So each
# run holds `<output>/.motion-claims/run-<run id>.lock` (JSON: run id, host, pid, scene,
# version, time) from before its bake to after its deliverables. Runs of the same version
# share the folder (shards, a second machine helping); a run that finds a live lock of
# another version refuses with one line naming it. Two runs of different versions that
# start at the same instant both write their lock before looking: the later one (by the time
# in the lock, then the run id) gives way, so exactly one goes on. A lock is live while its
# process is alive (same host) or, for another host, while its time is refreshed
# (every RUN_HEARTBEAT_S by a thread of the holder) within RUN_LOCK_STALE_S.

RUN_LOCK_PREFIX = "run-"
RUN_LOCK_SUFFIX = ".lock"
RUN_HEARTBEAT_S = 30.0
RUN_LOCK_STALE_S = 600.0
MAX_RUN_LOCKS = 1000  # lock files read at most (a folder flooded with them is refused, not read without end)


@dataclass(frozen=True)
class RunLock:
    """This run's lock on an output folder (release it with `release_run_lock`)."""

    path: Path
    run_id: str
    stop: threading.Event


def _lock_live(path: Path, info: dict) -> bool:
    """Whether another run's lock still stands (see the block comment above)."""
    try:
        age = time.time() - path.stat().st_mtime
    except OSError:
        return False
    if not info.get("run_id") or not isinstance(info.get("pid"), int) or isinstance(info.get("pid"), bool):
        return -WRITE_GRACE_S <= age <= WRITE_GRACE_S  # being written, or garbage
    if not 1 <= info["pid"] <= MAX_PID:
        return False  # no process has that pid, on any host
    if info.get("host") == _host() and not _pid_alive(info["pid"]):
        return False
    return -MAX_CLOCK_SKEW_S <= age <= RUN_LOCK_STALE_S


def _taken_order(info: dict) -> tuple[float, str]:
    """A run lock's sort key: when it was taken (an unreadable time last), then its run id."""
    t = info.get("time")
    return (float(t) if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t) else math.inf, str(info.get("run_id")))


def take_run_lock(out_dir: str | Path, who: Claimant, scene: str, version: str) -> RunLock:
    """Lock `out_dir` for this run of `scene` at `version` (a digest of everything a frame
    is made from). Raises OutputInUseError naming the other run when a live run of another
    version holds it; DiskFaultError when the disk refuses the lock."""
    from ..errors import OutputConfinementError, OutputInUseError
    from ..write_policy import confined

    folder = Path(out_dir) / CLAIM_DIR
    path = folder / f"{RUN_LOCK_PREFIX}{who.run_id}{RUN_LOCK_SUFFIX}"
    if not confined(out_dir, path):  # (frames in a subfolder: preflight never looked at this one)
        raise OutputConfinementError(f"{folder} is a link to {folder.resolve()}, outside the output folder {out_dir}: the run lock is written only inside it")
    mine = {**asdict(who), "scene": scene, "version": version, "time": time.time()}
    with disk_faults("locking the output folder", path):
        folder.mkdir(parents=True, exist_ok=True)
        write_atomic(path, json.dumps(mine).encode(), "locking the output folder")
    try:
        others = sorted(p for p in folder.glob(f"{RUN_LOCK_PREFIX}*{RUN_LOCK_SUFFIX}") if p != path)
    except OSError:
        others = []
    for other in others[:MAX_RUN_LOCKS]:
        info = read_claim(other)
        if info is None:
            continue
        if not _lock_live(other, info):
            _break_stale(other)
            continue
        if info.get("version") == version or _taken_order(info) > _taken_order(mine):
            continue  # the same version shares the folder; a later one gives way to us
        path.unlink(missing_ok=True)
        raise OutputInUseError(
            f"{out_dir}: another version of {str(info.get('scene'))[:200]!r} is being rendered here by run {str(info.get('run_id'))[:80]} "
            f"(pid {info.get('pid')} on {str(info.get('host'))[:80]}, lock {other}); rendering both would mix their frames: "
            f"wait for it, or render into another -o"
        )
    stop = threading.Event()

    def heartbeat() -> None:
        while not stop.wait(RUN_HEARTBEAT_S):
            try:
                os.utime(path)
            except OSError:
                return

    threading.Thread(target=heartbeat, name="motion-run-lock", daemon=True).start()
    return RunLock(path=path, run_id=who.run_id, stop=stop)


def release_run_lock(lock: RunLock) -> None:
    """Stop refreshing the lock and remove it (never raises: a lock a read-only disk keeps
    names a process that will be gone)."""
    lock.stop.set()
    try:
        lock.path.unlink(missing_ok=True)
    except OSError:
        pass
