"""Issue 29's proof on loopback: a real `dask scheduler` and two `dask worker` processes
that cannot see the client's folders (each worker in its own mount namespace, a tmpfs over
the folder holding the scene and the output). The render ships the parsed scene and its
assets, the frames come home bit-identical to a local run, and a hostile asset path is
refused before anything is sent."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from farm_util import DASK, TINY, frames_in, motion, report, stop_processes, wait_for
from motion.pipeline.frame_output import read_frame
from test_farm_dask import _free_port, _try, _workers_connected
from test_farm_transfer import _scene

UNSHARE = shutil.which("unshare")


def _namespaces_work(folder: Path) -> str | None:
    """None when a process can hide `folder` behind a tmpfs in its own mount namespace, else why not."""
    if UNSHARE is None or os.geteuid() != 0:
        return "needs root and unshare(1) to hide the client's folders from the workers"
    probe = subprocess.run([UNSHARE, "-m", "--propagation", "private", "sh", "-c", f"mount -t tmpfs tmpfs '{folder}' && test ! -e '{folder}/probe'"], capture_output=True, text=True)
    return None if probe.returncode == 0 else f"the kernel refuses a private mount namespace here: {probe.stderr.strip()}"


@pytest.fixture()
def hidden_cluster(tmp_path: Path):
    """`client/` holds the scene and the output; the workers see an empty tmpfs there."""
    client = tmp_path / "client"
    client.mkdir()
    (client / "probe").write_text("the client's")
    why = _namespaces_work(client)
    if why:
        pytest.skip(why)
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "MOTION_CACHE_DIR": str(tmp_path / "worker-cache")}
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)]
    for i in (1, 2):
        hide = f"mount -t tmpfs tmpfs '{client}' && exec {DASK} worker {address} --nthreads 1 --no-nanny --no-dashboard --host 127.0.0.1 --name w{i}"
        procs.append(subprocess.Popen([UNSHARE, "-m", "--propagation", "private", "sh", "-c", hide], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path, env=env))
    try:
        wait_for(lambda: _try(lambda: _workers_connected(address) == 2), 60, "two hidden dask workers")
        yield {"address": address, "client": client, "cache": tmp_path / "worker-cache"}
    finally:
        stop_processes(procs)


def test_workers_without_the_clients_folders_render_the_same_frames(hidden_cluster) -> None:
    client = hidden_cluster["client"]
    path = _scene(client / "shot", "tex.png")
    from PIL import Image

    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    Image.fromarray(np.stack([checker] * 3, axis=-1)).save(client / "shot" / "tex.png")
    path.write_text(path.read_text().replace("position: [0, 1, 9], look_at: [0, 0, 0]", "position: [0.3, 0.3, 2.5], look_at: [0.3, 0.3, 0]")
                    + "lights: [{type: constant, radiance: 1.0}]\n")
    common = ["--frames", "0-1", "--threads", "1", *TINY]
    local = motion("render", path, "-o", client / "local", *common)
    assert local.returncode == 0, local.stderr
    shipped = motion("render", path, "-o", client / "out", "--scheduler", hidden_cluster["address"], *common)  # --transfer auto
    assert shipped.returncode == 0, shipped.stderr
    rep = report(client / "out")
    assert rep["totals"]["rendered"] == 2, rep["totals"]
    got, want = frames_in(client / "out"), frames_in(client / "local")
    assert [p.name for p in got] == [p.name for p in want] and got
    for a, b in zip(got, want):
        assert np.array_equal(read_frame(a).rgba, read_frame(b).rgba)
    assert list((hidden_cluster["cache"] / "shipped").glob("*.png"))  # the texture came through the cluster
    # --check and resume work on the frames that came home
    assert motion("render", path, "-o", client / "out", "--check", *common).returncode == 0


def test_a_hostile_asset_path_is_refused_before_sending(hidden_cluster) -> None:
    client = hidden_cluster["client"]
    from PIL import Image

    Image.new("RGB", (4, 4), (9, 9, 9)).save(client / "secret.png")  # a real image: the asset checks pass, only the folder rule refuses it
    path = _scene(client / "shot", "../secret.png")
    res = motion("render", path, "-o", client / "out", "--scheduler", hidden_cluster["address"], "--transfer", "ship", "--frames", "0", *TINY)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    line = res.stderr.strip().splitlines()[-1]
    assert "outside the scene's folder" in line and "materials[0].color.file" in line, res.stderr
    assert not (hidden_cluster["cache"] / "shipped").exists()  # nothing reached a worker
