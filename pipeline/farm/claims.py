"""Frame claims: two renders into one folder never write the same frame twice.

Before a worker renders a frame it creates `<output>/.motion-claims/<frame file>.claim`
with `O_CREAT | O_EXCL` (atomic on local file systems and on NFSv3+), holding JSON with
the run id, host, pid and time. While the claim exists no other render touches the frame;
the worker removes it once the frame has been renamed into place (or has failed).

A claim found on disk is
- ours (same run id): a retry of our own chunk after its worker died; taken over;
- stale: its pid is gone on this host, or it is older than `stale_after_s` (default: the
  task timeout, which no live task outlives); broken by an atomic rename and re-claimed;
- live: the frame is left alone; the farm checks back later and re-queues it only if the
  other render gives up without finishing it.
"""

from __future__ import annotations

import json
import os
import socket
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

CLAIM_DIR = ".motion-claims"


@dataclass(frozen=True)
class Claimant:
    """Who holds a claim: the run (one `motion render` invocation) and the process."""

    run_id: str
    host: str
    pid: int

    @classmethod
    def here(cls, run_id: str) -> "Claimant":
        return cls(run_id=run_id, host=socket.gethostname(), pid=os.getpid())


def new_run_id() -> str:
    """A fresh id for one `motion render` invocation."""
    return f"{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def claim_path(frame_file: str | Path) -> Path:
    frame_file = Path(frame_file)
    return frame_file.parent / CLAIM_DIR / (frame_file.name + ".claim")


def read_claim(path: Path) -> dict | None:
    """The claim's content; {} if unreadable (being written); None if it is gone."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except OSError:
        return {}
    try:
        data = json.loads(text)
        return data if isinstance(data, dict) else {}
    except ValueError:
        return {}


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def is_stale(path: Path, info: dict, stale_after_s: float) -> bool:
    """A claim whose process is gone (same host) or that is older than the limit."""
    try:
        age = time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return True
    if info.get("host") == socket.gethostname() and isinstance(info.get("pid"), int):
        if not _pid_alive(info["pid"]):
            return True
    return age > stale_after_s


def try_claim(frame_file: str | Path, who: Claimant, stale_after_s: float) -> tuple[bool, dict | None]:
    """Claim a frame. Returns (True, None) when we hold it, else (False, holder info)."""
    path = claim_path(frame_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    body = json.dumps({**asdict(who), "time": time.time()}).encode()
    for _ in range(5):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            info = read_claim(path)
            if info is None:
                continue  # released between our open and our read: try again
            if info.get("run_id") == who.run_id:
                _rewrite(path, body)  # our own earlier attempt (its worker died): take over
                return True, None
            if is_stale(path, info, stale_after_s):
                # break it atomically: only one breaker's rename succeeds
                grave = path.with_name(f"{path.name}.stale.{os.getpid()}.{uuid.uuid4().hex[:6]}")
                try:
                    os.rename(path, grave)
                    grave.unlink(missing_ok=True)
                except FileNotFoundError:
                    pass
                continue
            return False, info
        else:
            with os.fdopen(fd, "wb") as f:
                f.write(body)
            return True, None
    info = read_claim(path)
    return False, info or {}


def _rewrite(path: Path, body: bytes) -> None:
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(body)
    os.replace(tmp, path)


def release(frame_file: str | Path, run_id: str) -> None:
    """Remove our claim on a frame (never someone else's)."""
    path = claim_path(frame_file)
    info = read_claim(path)
    if info is not None and info.get("run_id") == run_id:
        path.unlink(missing_ok=True)


def release_all(frame_files: list[str], run_id: str) -> None:
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
    except FileNotFoundError:
        pass
    return n
