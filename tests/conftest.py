"""Shared fixtures and the suite's layers. Helpers that tests import live in tests/support/
(`_support.py`, `farm_util.py`, ...: importable by name from every folder)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

# The farm's tests exercise spawned worker processes (kills, retries, Ctrl-C); a small job
# would otherwise render inline (farm/inline.py). Tests of that choice set it themselves.
os.environ.setdefault("MOTION_EXECUTOR", "local")

from _support import run_motion

# The suite's own folders (gitignored), never the user's: one per session (`session-<pid>-*`:
# pytest's basetemp `tmp/`, and `cache/`, the cache root every test and every `motion` it
# starts uses through $MOTION_CACHE_DIR), removed when the session passes and by the next
# session once its process is gone; and `kernels/`, drjit's kernel cache ($DRJIT_CACHE_DIR),
# kept between sessions so the suite does not compile Mitsuba's kernels every run.
SCRATCH = Path(__file__).resolve().parents[1] / ".pytest-tmp"
SESSION = pytest.StashKey[Path]()
PASSED = pytest.StashKey[bool]()


def _sweep(scratch: Path) -> None:
    """Remove the session folders of test sessions whose process has ended."""
    for folder in scratch.glob("session-*"):
        try:
            pid = int(folder.name.split("-")[1])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(folder, ignore_errors=True)
        except (ValueError, IndexError, PermissionError):
            continue


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    """The session's folders and cache root, before pytest makes its basetemp (an xdist
    worker takes its controller's: the environment and a basetemp below the controller's)."""
    if hasattr(config, "workerinput"):
        return
    SCRATCH.mkdir(exist_ok=True)
    _sweep(SCRATCH)
    session = Path(tempfile.mkdtemp(prefix=f"session-{os.getpid()}-", dir=SCRATCH))
    config.stash[SESSION] = session
    if not config.option.basetemp:
        config.option.basetemp = str(session / "tmp")
    os.environ["MOTION_CACHE_DIR"] = str(session / "cache")
    os.environ["DRJIT_CACHE_DIR"] = str(SCRATCH / "kernels")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Note whether the session passed (its folders are then removed)."""
    session.config.stash[PASSED] = exitstatus == 0


def pytest_unconfigure(config: pytest.Config) -> None:
    """A session that passed leaves nothing behind; a failed one keeps its folder (frames,
    reports to look at) until the next session."""
    folder = config.stash.get(SESSION, None)
    if folder is None:
        return
    if config.stash.get(PASSED, False):
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def motion_cli():
    return run_motion


CLI_TIER = Path(__file__).resolve().parent / "cli"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every test under tests/cli/ (it drives the installed `motion` command and reads what
    it prints) carries the `cli` marker, so the layer runs or is skipped as one
    (`-m cli`, `-m "not cli"`) and a new file there cannot forget it."""
    for item in items:
        if item.path.is_relative_to(CLI_TIER):
            item.add_marker(pytest.mark.cli)
