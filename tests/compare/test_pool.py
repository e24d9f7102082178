"""The compare pool's stop path leaves nothing for the interpreter's exit hook to race."""

from __future__ import annotations

import threading
import time
from concurrent.futures import process as pool_internals
from pathlib import Path

import pytest

from motion.pipeline.compare import comparison


def test_a_failed_pool_is_taken_off_the_exit_hook(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame that cannot be read fails the pool; its processes end, and its manager
    thread is joined and gone from concurrent.futures' exit hook, whose unguarded write
    to the manager's closing wake-up pipe printed a traceback at exit on a busy host.
    The busy host is played by a manager that takes a second to wind down."""
    slow = pool_internals._ExecutorManagerThread.join_executor_internals

    def busy_host(manager: object) -> None:
        time.sleep(1.0)
        slow(manager)

    monkeypatch.setattr(pool_internals._ExecutorManagerThread, "join_executor_internals", busy_host)
    hooked_before, threads_before = set(pool_internals._threads_wakeups.keys()), set(threading.enumerate())
    missing = str(tmp_path / "nothing.exr")
    with pytest.raises(Exception):
        comparison._in_pool([(0, missing, missing), (1, missing, missing)], 2, flip="all", alpha=0.05, keep_maps=False)
    assert set(pool_internals._threads_wakeups.keys()) <= hooked_before
    assert set(threading.enumerate()) <= threads_before
