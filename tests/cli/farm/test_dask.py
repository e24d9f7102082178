"""A real Dask cluster on loopback: `dask scheduler` and two `dask worker` processes
started here; one worker is SIGKILLed mid-job. Every frame completes, each valid, and only
the killed chunk is retried."""

from __future__ import annotations

import socket
import subprocess

import pytest

from farm_util import DASK, SCENE, SLOW, TINY, frames_in, kill, leftovers, motion, report, start_motion, stop_processes, wait_for
from motion.pipeline.frame_output import read_frame

pytestmark = pytest.mark.render


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _workers_connected(address: str) -> int:
    from distributed import Client

    with Client(address, timeout=10) as c:
        return len(c.scheduler_info(n_workers=-1)["workers"])


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two single-threaded workers (no nanny: a killed worker stays dead)."""
    logs = tmp_path_factory.mktemp("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs: list[subprocess.Popen] = []

    def spawn(args: list[str], name: str) -> subprocess.Popen:
        p = subprocess.Popen([DASK, *args], stdout=open(logs / f"{name}.out", "w"), stderr=subprocess.STDOUT, cwd=logs)
        procs.append(p)
        return p

    spawn(["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], "scheduler")
    workers = [
        spawn(["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard", "--host", "127.0.0.1", "--name", f"w{i}"], f"worker{i}")
        for i in (1, 2)
    ]
    try:
        wait_for(lambda: _try(lambda: _workers_connected(address) == 2), 60, "two dask workers")
        yield {"address": address, "workers": workers}
    finally:
        stop_processes(procs)


def _try(fn) -> bool:
    try:
        return bool(fn())
    except Exception:
        return False


def test_dask_renders_same_frames_as_local(cluster, tmp_path) -> None:
    out, local = tmp_path / "dask", tmp_path / "local"
    res = motion("render", SCENE, "-o", out, "--frames", "0-7", "--scheduler", cluster["address"], "--threads", "1", *TINY)
    assert res.returncode == 0, res.stderr
    rep = report(out)
    assert rep["executor"]["kind"] == "dask" and rep["totals"]["rendered"] == 8
    assert len({r["worker"] for r in rep["frames"]}) == 2  # both workers took chunks
    res = motion("render", SCENE, "-o", local, "--frames", "0-7", *TINY)
    assert res.returncode == 0, res.stderr
    for f in range(8):
        name = f"farm-tiny.{f:04d}.exr"
        assert (read_frame(out / name).rgba == read_frame(local / name).rgba).all()
    # the first-frame cache lives on in the worker processes: a second job (same settings)
    # renders no cold frame at all
    res = motion("render", SCENE, "-o", out, "--frames", "0-7", "--scheduler", cluster["address"], "--threads", "1", "--overwrite", *TINY)
    assert res.returncode == 0, res.stderr
    assert report(out)["totals"]["cold_frames"] == 0


def test_dask_worker_killed_mid_job(cluster, tmp_path) -> None:
    out = tmp_path / "out"
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-15", "--scheduler", cluster["address"], "--threads", "1", "--chunk-size", "4", *SLOW)
    wait_for(lambda: len(frames_in(out)) >= 2, 90, "first frames")
    victim = cluster["workers"][0]
    kill(victim.pid)
    stdout, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 0, stderr
    for f in range(16):
        assert read_frame(out / f"farm-tiny.{f:04d}.exr").meta["frame"] == f
    rep = report(out)
    assert rep["totals"]["rendered"] + rep["totals"]["skipped"] == 16 and rep["totals"]["failed"] == 0
    lost = [w for w in rep["workers"] if w["lost"]]
    assert len(lost) == 1, rep["workers"]
    retried = [r["frame"] for r in rep["frames"] if r["attempts"] > 1]
    assert 1 <= len(retried) <= 4 and retried == list(range(retried[0], retried[0] + len(retried)))
    assert all(r["attempts"] == 1 for r in rep["frames"] if r["frame"] not in retried)
    # the killed worker's frames were all rendered by the survivor
    survivor = {r["worker"] for r in rep["frames"] if r["frame"] in retried and r["status"] == "rendered"}
    assert len(survivor) <= 1 and not any(w.endswith(f":{victim.pid}") for w in survivor)
    assert not leftovers(out)


def test_dask_progress_is_per_frame(cluster, tmp_path) -> None:
    """One chunk of 8 frames on the cluster: progress reports frames while the chunk still
    runs (the worker logs each written frame to the scheduler)."""
    import threading

    out = tmp_path / "out"
    lines = [a for a in SLOW if a != "--no-progress"]  # stderr is not a terminal: plain progress lines
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-7", "--scheduler", cluster["address"], "--threads", "1", "--chunk-size", "8", *lines)
    on_disk_at_first_line: list[int] = []

    def read() -> None:
        for line in proc.stderr:
            if line.startswith("  farm-tiny: ") and "/8 frames" in line and not on_disk_at_first_line:
                on_disk_at_first_line.append(len(frames_in(out)))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    proc.wait(timeout=180)
    reader.join(10)
    assert proc.returncode == 0
    # per chunk, the first line would come when all 8 frames are on disk
    assert on_disk_at_first_line and on_disk_at_first_line[0] < 8, on_disk_at_first_line
    assert report(out)["totals"]["rendered"] == 8
