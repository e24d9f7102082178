"""The compare pool's stop path leaves nothing for the interpreter's exit hook to race."""

from __future__ import annotations

import signal
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


def test_a_stop_while_a_pool_runs_is_noted_then_raised_on_the_way_out() -> None:
    """A Ctrl-C is noted while the pool runs (the wait acts on it) and raised as
    KeyboardInterrupt when the pool is left, with the handler put back."""
    assert threading.current_thread() is threading.main_thread()  # (xdist runs tests there)
    # Ctrl-C as a terminal gives it (an xdist worker ignores SIGINT, and so would we)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with comparison._stops_held() as stops:
                signal.raise_signal(signal.SIGINT)
                assert stops == [signal.SIGINT]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)


def test_an_ignored_sigint_stays_ignored() -> None:
    """A SIGINT the process ignores (nohup, a background job of a shell) is not a stop: the
    noted-then-raised stop of a pool, ignored on the way out, escaped as an error (exit 1
    with a traceback in a test session that ignored SIGINT)."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with comparison._stops_held() as stops:
            signal.raise_signal(signal.SIGINT)
        assert stops == [] and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
