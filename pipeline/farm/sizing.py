"""How big a local job is: its worker processes, each one's drjit threads, and the GPUs they
are spread over, with the limits on what a user may ask for. Apart from the executor
(farm/local.py), whose multiprocessing a run that renders nothing never loads."""

from __future__ import annotations

import os

MAX_DEFAULT_WORKERS = 8  # each worker keeps its own scene and kernels in memory
MAX_WORKERS = 256  # local worker processes
MAX_THREADS = 1024  # drjit threads per worker
MAX_RETRIES = 100  # extra attempts per chunk


def threads_per_worker(workers: int, cores: int | None = None) -> int:
    """drjit threads for each of `workers` processes: max(1, cores // workers)."""
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, cores // max(1, workers))


def default_workers(frames: int, gpus: int = 0) -> int:
    """All local cores by default: one worker per core (each gets cores // workers drjit
    threads), no more than there are frames, at most MAX_DEFAULT_WORKERS (docs/farm.md
    gives the measurement behind one worker per core). On a CUDA variant (`gpus`: the
    devices `worker_devices` found) one worker per GPU instead: a worker's megakernel fills
    its GPU, and more workers per GPU only add CUDA contexts, scenes and compiled kernels
    to its memory."""
    units = gpus if gpus > 0 else threads_per_worker(1)
    return max(1, min(units, frames, MAX_DEFAULT_WORKERS))


def worker_devices(variant: str) -> list[str]:
    """The GPUs local workers are spread over, one each in turn (CUDA_VISIBLE_DEVICES):
    the devices this process may use (`variant.gpu_devices`) when `variant` renders on
    CUDA here (requested, or `auto` with a working GPU); none otherwise."""
    from ..variant import choose, gpu_devices

    devices = gpu_devices()
    if not devices or variant in ("llvm_ad_rgb", "scalar_rgb"):
        return []
    return devices if choose(variant).variant.startswith("cuda") else []
