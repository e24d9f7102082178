"""Where motion keeps its on-disk caches (converted assets, imports, kernels, the variant
probe): one root, shared by every stage that caches."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """Root of motion's on-disk caches: $MOTION_CACHE_DIR, else $XDG_CACHE_HOME/motion."""
    env = os.environ.get("MOTION_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "motion"


def kernels_dir() -> Path:
    """drjit's kernel cache: $DRJIT_CACHE_DIR, else kernels/ under the cache root."""
    return Path(os.environ.get("DRJIT_CACHE_DIR", str(cache_root() / "kernels")))
