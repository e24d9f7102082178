"""Engine warnings that mean wrong pixels fail the frame (docs/rendering.md).

drjit reports what it does instead of failing, and some of it leaves the image wrong while
the render "succeeds": on CUDA a kernel that traces scenes of more than one OptiX pipeline
or shader binding table gets each later trace disabled ("... Disabling this ray tracing
operation to avoid potential undefined behavior."), which reads as a miss. drjit 1.5's
Python module receives every drjit log message of level Warn and above through its log
callback and writes it to `sys.stderr` (drjit src/python/log.cpp); `watching()` puts a
tee there while a frame renders, the message still reaches the console, and a frame whose
messages match `WRONG_PIXELS` raises `EngineWarningError`: one line naming the cause, the
frame fails (the job exits 3 after the others).
"""

from __future__ import annotations

import sys
import threading
from contextlib import contextmanager
from typing import Any, Iterator

# substring of a drjit message -> what it means for the frame (one entry per cause)
WRONG_PIXELS: dict[str, str] = {
    "Disabling this ray tracing operation": "drjit disabled ray tracing in a kernel that traced scenes of more than one OptiX pipeline or shader binding table (rays read as misses)",
}


class EngineWarningError(RuntimeError):
    """The engine warned, during this frame, of something that makes its pixels wrong."""


class Watch:
    """The matching messages seen while one `watching()` block ran: [(cause, message)]."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, str]] = []

    def check(self) -> None:
        """Raise EngineWarningError (one line) if a message meant wrong pixels."""
        if not self.seen:
            return
        cause, message = self.seen[0]
        first = " ".join(message.split()).split(", which")[0].split(". ")[0]  # its first clause
        times = f" ({len(self.seen)} times)" if len(self.seen) > 1 else ""
        raise EngineWarningError(f"{cause}{times}; drjit: {first[:160]}")


_lock = threading.Lock()
_active: list[tuple[int, Watch]] = []  # (thread id, watch) of every open block


def _record(text: str) -> None:
    """Give `text` to the watches of the writing thread (all open ones when it has none:
    drjit may log from a thread of its own; a frame is never left silent)."""
    causes = [(cause, text) for needle, cause in WRONG_PIXELS.items() if needle in text]
    if not causes:
        return
    me = threading.get_ident()
    with _lock:
        mine = [w for t, w in _active if t == me] or [w for _, w in _active]
    for w in mine:
        w.seen.extend(causes)


class _Tee:
    """`sys.stderr` while a frame renders: every write goes on to the stream it replaced,
    and drjit's messages are matched against WRONG_PIXELS on the way."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner

    def write(self, text: str) -> int:
        """Pass `text` on; record it if it means wrong pixels."""
        _record(str(text))
        return int(self.inner.write(text) or 0)

    def flush(self) -> None:
        """Flush the stream it replaced."""
        self.inner.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


@contextmanager
def watching() -> Iterator[Watch]:
    """Watch drjit's log for the block; `Watch.check()` after it raises if the frame's
    pixels are wrong. drjit's log level is raised to Warn if it was below (its callback
    then receives the warnings). Nested and concurrent blocks share one tee."""
    import drjit as dr

    if dr.log_level().value < dr.LogLevel.Warn.value:
        dr.set_log_level(dr.LogLevel.Warn)
    watch = Watch()
    entry = (threading.get_ident(), watch)
    with _lock:
        if not isinstance(sys.stderr, _Tee):
            sys.stderr = _Tee(sys.stderr)
        _active.append(entry)
    try:
        yield watch
    finally:
        with _lock:
            _active.remove(entry)
            if not _active and isinstance(sys.stderr, _Tee):
                sys.stderr = sys.stderr.inner
