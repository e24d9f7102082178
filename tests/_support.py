"""Shared test helpers (importable as `_support`): run the real `motion` command."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "scenes"
MOTION = str(Path(sys.executable).with_name("motion"))


def run_motion(*args: str, env: dict[str, str] | None = None, timeout: float = 300, cwd: str | Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run `motion ARGS...` in a subprocess as a user would; returns the completed process."""
    full_env = dict(os.environ)
    if env:
        full_env.update(env)
    return subprocess.run([MOTION, *args], capture_output=True, text=True, timeout=timeout, env=full_env, cwd=cwd or REPO)
