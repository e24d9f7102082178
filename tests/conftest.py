"""Shared fixtures. Helpers that tests import live in `_support.py`."""

from __future__ import annotations

import pytest

from _support import run_motion


@pytest.fixture
def motion_cli():
    return run_motion
