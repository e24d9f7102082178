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


def kernel_cache_key() -> str:
    """`motion-kernels-<16 hex>`: what compiled kernels depend on besides the scene (the
    Mitsuba, drjit and motion versions, Python's, the machine and the CPU's model and
    features, the libLLVM in use), for a CI system's cache key. Reads versions from the
    installed packages' metadata: nothing is imported."""
    import hashlib
    import platform
    from importlib.metadata import PackageNotFoundError, version

    parts = [platform.python_version(), platform.machine(), os.environ.get("DRJIT_LIBLLVM_PATH", "")]
    for dist in ("mitsuba", "drjit", "motion-farm"):
        try:
            parts.append(f"{dist}={version(dist)}")
        except PackageNotFoundError:
            parts.append(f"{dist}=?")
    try:
        cpu = Path("/proc/cpuinfo").read_text()
        model = next((line for line in cpu.splitlines() if line.startswith("model name")), "")
        flags = next((line for line in cpu.splitlines() if line.startswith("flags")), "")
        parts += [model, flags]
    except OSError:
        parts.append(platform.processor())
    return "motion-kernels-" + hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]
