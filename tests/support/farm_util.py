"""Helpers for the farm tests: run `motion` as a real process, find its workers, read
frames and reports."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import psutil

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "tests" / "data" / "farm-tiny.yaml"
BIN = Path(sys.executable).parent
MOTION = str(BIN / "motion")
DASK = str(BIN / "dask")
TINY = ["--resolution", "16x12", "--spp", "1", "--no-progress"]
# slow enough (~0.2-0.3 s a frame) to kill or interrupt a job half way
SLOW = ["--resolution", "96x72", "--spp", "128", "--no-progress"]


def motion(*args: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([MOTION, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def as_from_a_terminal() -> None:
    """In the child, before exec: SIGINT as a shell gives it (default action, unblocked).
    A process inherits an ignored disposition and a blocked mask across exec, and a test
    session that touched either (libraries, earlier tests) would make Ctrl-C tests lie."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def start_motion(*args: str, cwd: Path | None = None) -> subprocess.Popen:
    return subprocess.Popen(
        [MOTION, *map(str, args)], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=as_from_a_terminal
    )


def wait_for(pred: Callable[[], bool], timeout: float = 60, what: str = "condition") -> None:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def worker_pids(pid: int) -> list[int]:
    """The farm worker processes (spawned children) of a `motion render` process."""
    out = []
    for child in psutil.Process(pid).children(recursive=True):
        try:
            cmd = " ".join(child.cmdline())
        except psutil.Error:
            continue
        if "spawn_main" in cmd and "resource_tracker" not in cmd:
            out.append(child.pid)
    return out


def frames_in(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.exr"))


def report(folder: Path, name: str = "render-report.json") -> dict:
    return json.loads((folder / name).read_text())


def leftovers(folder: Path) -> list[Path]:
    """Temporary frame files and claims that should never outlive a render."""
    tmps = list(folder.glob(".*.tmp"))
    claims = list((folder / ".motion-claims").glob("*")) if (folder / ".motion-claims").exists() else []
    return tmps + claims


def stop_processes(procs: list[subprocess.Popen]) -> None:
    """Terminate a test cluster's processes (last started first), killing any that linger."""
    for p in reversed(procs):
        p.terminate()
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()


def kill(pid: int, sig: int = signal.SIGKILL) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass


def _auto(env_extra: dict[str, str] | None = None) -> dict[str, str]:
    """This environment without MOTION_EXECUTOR (the suite's conftest sets it to `local`), so
    `motion` chooses its executor itself; `env_extra` added."""
    env = {k: v for k, v in os.environ.items() if k != "MOTION_EXECUTOR"}
    return {**env, **(env_extra or {})}
