"""Shared fixtures. Helpers that tests import live in `_support.py`."""

from __future__ import annotations

import os

import pytest

# The farm's tests exercise spawned worker processes (kills, retries, Ctrl-C); a small job
# would otherwise render inline (farm/inline.py). Tests of that choice set it themselves.
os.environ.setdefault("MOTION_EXECUTOR", "local")

from _support import run_motion


@pytest.fixture
def motion_cli():
    return run_motion
