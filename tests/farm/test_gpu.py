"""A farm on GPU machines, checked without one (issue 35): workers sized by GPUs on a CUDA
variant, one GPU per local worker (CUDA_VISIBLE_DEVICES), Dask GPU jobs only on workers
that advertise a GPU, and the report naming each frame's variant and device. The GPU
count is what `nvidia-smi -L` would list, given as its text."""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import pytest

from farm_util import DASK, SCENE, TINY, motion, stop_processes, wait_for

H100_X2 = "GPU 0: NVIDIA H100 80GB HBM3 (UUID: GPU-4f1c)\nGPU 1: NVIDIA H100 80GB HBM3 (UUID: GPU-9e07)\n"


def test_gpus_are_those_cuda_would_show() -> None:
    from motion.pipeline.variant import gpu_devices

    assert gpu_devices(listing=H100_X2, env={}) == ["0", "1"]
    assert gpu_devices(listing="", env={}) == []  # nvidia-smi listed none
    assert gpu_devices(listing=H100_X2, env={"CUDA_VISIBLE_DEVICES": "1"}) == ["1"]  # the user's choice wins
    assert gpu_devices(listing=H100_X2, env={"CUDA_VISIBLE_DEVICES": ""}) == []
    assert gpu_devices(listing=H100_X2, env={"CUDA_VISIBLE_DEVICES": "GPU-9e07,-1,0"}) == ["GPU-9e07"]  # CUDA stops at -1


def test_no_nvidia_smi_means_no_gpu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.variant import gpu_devices

    monkeypatch.setenv("PATH", str(tmp_path))  # a PATH without nvidia-smi
    assert gpu_devices(env={}) == []


def test_workers_are_sized_by_gpus_on_cuda_and_by_cores_otherwise() -> None:
    from motion.pipeline.farm.sizing import MAX_DEFAULT_WORKERS, default_workers, threads_per_worker

    cores = threads_per_worker(1)
    assert default_workers(100, gpus=1) == 1  # the 16-core H100 machine: one worker, not 8
    assert default_workers(100, gpus=2) == 2
    assert default_workers(1, gpus=4) == 1  # never more workers than frames
    assert default_workers(100, gpus=64) == MAX_DEFAULT_WORKERS
    assert default_workers(100, gpus=0) == min(cores, MAX_DEFAULT_WORKERS)


def test_a_cpu_variant_spreads_no_gpus(monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.farm.sizing import worker_devices

    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1")
    assert worker_devices("llvm_ad_rgb") == [] and worker_devices("scalar_rgb") == []


def _environ(pid: int) -> dict[str, str]:
    """A worker's environment as its program started with it (after its exec: before it,
    /proc shows the parent's first environment)."""
    wait_for(lambda: b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes(), 30, f"worker {pid} started")
    raw = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    return dict(item.decode().split("=", 1) for item in raw if b"=" in item)


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="reads a worker's environment from /proc")
def test_each_local_worker_gets_its_own_gpu_and_a_replacement_keeps_it(monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.farm.local import LocalExecutor

    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    executor = LocalExecutor(3, devices=["0", "1"])
    try:
        seen = sorted(_environ(pid).get("CUDA_VISIBLE_DEVICES", "-") for pid in executor.pids)
        assert seen == ["0", "0", "1"]  # in turn
        assert "CUDA_VISIBLE_DEVICES" not in os.environ  # this process's own is untouched
        name = next(n for n, w in executor._workers.items() if w.device == "1")
        executor.stop_worker(name, "excluded")
        assert sorted(_environ(pid).get("CUDA_VISIBLE_DEVICES", "-") for pid in executor.pids) == ["0", "0", "1"]
    finally:
        executor.close()
    plain = LocalExecutor(1)
    try:
        assert "CUDA_VISIBLE_DEVICES" not in _environ(plain.pids[0])
    finally:
        plain.close()


@pytest.mark.render
def test_the_report_names_each_frames_variant_and_device(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY)
    assert res.returncode == 0, res.stderr
    rows = json.loads((out / "render-report.json").read_text())["frames"]
    assert [r["frame"] for r in rows] == [0, 1]
    for row in rows:
        assert row["variant"] in ("llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb")
        assert row["device"] == ("cpu" if not row["variant"].startswith("cuda") else f"cuda:{os.environ.get('CUDA_VISIBLE_DEVICES') or '0'}")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_cuda_job_goes_only_to_dask_workers_that_advertise_a_gpu(tmp_path: Path) -> None:
    from distributed import Client

    from motion.pipeline.errors import UsageError
    from motion.pipeline.farm.cluster import DaskExecutor

    address = f"tcp://127.0.0.1:{_free_port()}"
    procs: list[subprocess.Popen[bytes]] = []

    def spawn(*args: str) -> None:
        procs.append(subprocess.Popen([DASK, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path))

    def workers() -> int:
        with Client(address, timeout=10) as c:
            return len(c.scheduler_info(n_workers=-1)["workers"])

    spawn("scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1], "--no-dashboard")
    common = ["--nthreads", "1", "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"]
    try:
        spawn("worker", address, *common, "--name", "cpu")
        wait_for(lambda: _try(lambda: workers() == 1), 60, "a CPU worker")
        with pytest.raises(UsageError, match="no worker of .* advertises a GPU.*--resources GPU=1"):
            DaskExecutor(address, gpu=True)
        spawn("worker", address, *common, "--name", "gpu", "--resources", "GPU=1")
        wait_for(lambda: _try(lambda: workers() == 2), 60, "a GPU worker")
        gpu_job, any_job = DaskExecutor(address, gpu=True), DaskExecutor(address)
        try:
            with Client(address, timeout=10) as c:
                info = c.scheduler_info(n_workers=-1)["workers"]
            gpu_address = next(a for a, w in info.items() if w.get("name") == "gpu")
            assert gpu_job.live_workers() == gpu_job.idle_workers() == [gpu_address]
            assert len(any_job.live_workers()) == 2
        finally:
            gpu_job.close()
            any_job.close()
    finally:
        stop_processes(procs)


def _try(fn) -> bool:  # type: ignore[no-untyped-def]
    try:
        return bool(fn())
    except Exception:
        return False
