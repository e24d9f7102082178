"""Issue 29's proof on loopback: a real `dask scheduler` and two `dask worker` processes
that cannot see the client's folders (each worker in its own mount namespace, a tmpfs over
the folder holding the scene and the output). The render ships the parsed scene and its
assets, the frames come home bit-identical to a local run, and a hostile asset path is
refused before anything is sent."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from farm_util import DASK, SLOW, TINY, frames_in, kill, leftovers, motion, report, start_motion, stop_processes, wait_for
from motion.pipeline.frame_output import read_frame
from tests.cli.farm.test_dask import _free_port, _try, _workers_connected
from tests.farm.test_transfer import _scene

pytestmark = pytest.mark.render

UNSHARE = shutil.which("unshare")


def _namespaces_work(folder: Path) -> str | None:
    """None when a process can hide `folder` behind a tmpfs in its own mount namespace, else why not."""
    if UNSHARE is None or os.geteuid() != 0:
        return "needs root and unshare(1) to hide the client's folders from the workers"
    probe = subprocess.run([UNSHARE, "-m", "--propagation", "private", "sh", "-c", f"mount -t tmpfs tmpfs '{folder}' && test ! -e '{folder}/probe'"], capture_output=True, text=True)
    return None if probe.returncode == 0 else f"the kernel refuses a private mount namespace here: {probe.stderr.strip()}"


@pytest.fixture(scope="module")
def hidden_cluster(tmp_path_factory):
    """`client/` holds the scenes and the outputs; the workers see an empty tmpfs there.
    Worker w1 keeps its cache on a 96 KiB tmpfs of its own (a small cache disk)."""
    tmp_path = tmp_path_factory.mktemp("ship")
    client = tmp_path / "client"
    client.mkdir()
    (client / "probe").write_text("the client's")
    why = _namespaces_work(client)
    if why:
        pytest.skip(why)
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)]
    workers = {}
    for name in ("w1", "w2"):
        cache = tmp_path / f"cache-{name}"
        cache.mkdir()
        small = f" && mount -t tmpfs -o size=96k tmpfs '{cache}'" if name == "w1" else ""
        hide = f"mount -t tmpfs tmpfs '{client}'{small} && exec {DASK} worker {address} --nthreads 1 --no-nanny --no-dashboard --host 127.0.0.1 --name {name}"
        env = {**os.environ, "MOTION_CACHE_DIR": str(cache)}
        workers[name] = subprocess.Popen([UNSHARE, "-m", "--propagation", "private", "sh", "-c", hide], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path, env=env)
        procs.append(workers[name])
    try:
        wait_for(lambda: _try(lambda: _workers_connected(address) == 2), 60, "two hidden dask workers")
        yield {"address": address, "client": client, "cache": tmp_path / "cache-w2", "workers": workers}
    finally:
        stop_processes(procs)


def _textured(folder: Path, texture: np.ndarray) -> Path:
    """The textured two-triangle scene of test_farm_transfer, framed close, with `texture`."""
    from PIL import Image

    path = _scene(folder, "tex.png")
    Image.fromarray(texture).save(folder / "tex.png")
    path.write_text(path.read_text().replace("last: 1", "last: 7").replace("position: [0, 1, 9], look_at: [0, 0, 0]", "position: [0.3, 0.3, 2.5], look_at: [0.3, 0.3, 0]")
                    + "lights: [{type: constant, radiance: 1.0}]\n")
    return path


def test_workers_without_the_clients_folders_render_the_same_frames(hidden_cluster) -> None:
    client = hidden_cluster["client"]
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    path = _textured(client / "shot", np.stack([checker] * 3, axis=-1))
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
    sent = rep["executor"]["transfer"]
    assert sent["mode"] == "ship" and sent["assets"] == 2 and 0 < sent["asset_bytes_to_workers"] <= 2 * sent["asset_bytes"]  # once per worker at most
    assert sent["asset_bytes_from_client"] == sent["asset_bytes"]  # the client uploads each once; workers pass them on
    assert sent["frame_bytes_home"] == sum(p.stat().st_size for p in got)
    again = motion("render", path, "-o", client / "out", "--scheduler", hidden_cluster["address"], "--overwrite", *common)
    assert again.returncode == 0, again.stderr
    moved = report(client / "out")["executor"]["transfer"]
    assert moved["asset_bytes_to_workers"] == moved["asset_bytes_from_client"] == 0  # the workers' caches kept them
    # --check and resume work on the frames that came home
    assert motion("render", path, "-o", client / "out", "--check", *common).returncode == 0


def test_an_imported_skinned_character_ships(hidden_cluster, monkeypatch: pytest.MonkeyPatch) -> None:
    """scenes/walker.yaml imports a skinned, keyframed glTF: its expansion names converted
    meshes, textures, morph targets and skin arrays by absolute path in the client's import
    cache, which the workers cannot see either (kept inside the hidden folder here). They
    travel as `.motion-imports/<name>`; the frames equal a local render's."""
    client = hidden_cluster["client"]
    root = Path(__file__).resolve().parents[3]
    shutil.copytree(root / "scenes" / "assets", client / "walker" / "assets")
    shutil.copy(root / "scenes" / "walker.yaml", client / "walker" / "walker.yaml")
    monkeypatch.setenv("MOTION_CACHE_DIR", str(client / "client-cache"))  # the client's import cache: hidden too
    common = ["--frames", "0-1", "--threads", "1", *TINY]
    path = client / "walker" / "walker.yaml"
    local = motion("render", path, "-o", client / "walker-local", *common)
    assert local.returncode == 0, local.stderr
    shipped = motion("render", path, "-o", client / "walker-out", "--scheduler", hidden_cluster["address"], *common)
    assert shipped.returncode == 0, shipped.stderr
    got, want = frames_in(client / "walker-out"), frames_in(client / "walker-local")
    assert [p.name for p in got] == [p.name for p in want] == ["walker.0000.exr", "walker.0001.exr"]
    for a, b in zip(got, want):
        assert np.array_equal(read_frame(a).rgba, read_frame(b).rgba)
    assert report(client / "walker-out")["executor"]["transfer"]["mode"] == "ship"


def test_auto_ships_when_only_the_output_folder_is_hidden(hidden_cluster) -> None:
    """The scene lies where the workers can read it, `-o` where they cannot: writing frames
    there would leave them on the workers' disks, so --transfer auto ships."""
    visible = hidden_cluster["client"].parent / "visible"
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    path = _textured(visible / "shot", np.stack([checker] * 3, axis=-1))
    out = hidden_cluster["client"] / "out-auto"
    res = motion("render", path, "-o", out, "--scheduler", hidden_cluster["address"], "--frames", "0-1", "--threads", "1", *TINY)
    assert res.returncode == 0, res.stderr
    assert report(out)["executor"]["transfer"]["mode"] == "ship"
    assert [p.name for p in frames_in(out)] == ["scene.0000.exr", "scene.0001.exr"]
    assert not list(out.glob(".motion-transfer-probe-*"))


def test_a_hostile_asset_path_is_refused_before_sending(hidden_cluster) -> None:
    client = hidden_cluster["client"]
    from PIL import Image

    Image.new("RGB", (4, 4), (9, 9, 9)).save(client / "secret.png")  # a real image: the asset checks pass, only the folder rule refuses it
    path = _scene(client / "shot", "../secret.png")
    res = motion("render", path, "-o", client / "out", "--scheduler", hidden_cluster["address"], "--transfer", "ship", "--frames", "0", *TINY)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    line = res.stderr.strip().splitlines()[-1]
    assert "outside the scene's folder" in line and "materials[0].color.file" in line, res.stderr
    secret = hashlib.sha256((client / "secret.png").read_bytes()).hexdigest()
    assert not list(hidden_cluster["cache"].rglob(f"{secret}*"))  # nothing reached a worker


def test_a_worker_whose_cache_disk_is_full_says_so_in_one_line(hidden_cluster) -> None:
    """w1's 96 KiB cache disk cannot take a 192 KiB texture: its chunk fails with one line
    naming the worker and the full disk, and is retried on w2; the job finishes, with this
    scene's texture (warm workers keyed their scene by the assets' contents too)."""
    client = hidden_cluster["client"]
    noise = np.random.default_rng(5).integers(0, 256, (256, 256, 3), dtype=np.uint8)  # does not compress
    path = _textured(client / "big", noise)
    out = client / "out-big"
    res = motion("render", path, "-o", out, "--scheduler", hidden_cluster["address"], "--transfer", "ship", "--frames", "0-3", "--chunk-size", "1", "--threads", "1", *TINY)
    assert res.returncode == 0, res.stderr
    rep = report(out)
    assert rep["totals"]["rendered"] == 4 and rep["totals"]["failed"] == 0
    errors = [e for r in rep["frames"] for e in r.get("errors", [])]
    assert errors and all("\n" not in e and "No space left on device" in e and "caching a shipped asset" in e for e in errors), errors
    w1 = [w for w in rep["workers"] if w["failures"]]
    assert w1 and all(w["frames"] == 0 for w in w1)  # every frame came from the worker with room
    assert any("No space left on device" in line for line in res.stderr.splitlines())
    # same scene text as the first test's shot, another texture: no worker reused that scene
    local = motion("render", path, "-o", client / "local-big", "--frames", "0", "--threads", "1", *TINY)
    assert local.returncode == 0, local.stderr
    assert np.array_equal(read_frame(out / "scene.0000.exr").rgba, read_frame(client / "local-big" / "scene.0000.exr").rgba)


def test_a_worker_killed_mid_chunk_is_retried(hidden_cluster) -> None:
    """SIGKILL the worker holding a shipped chunk: the chunk is retried on the other worker
    (last in this module: the killed worker stays dead)."""
    from distributed import Client

    client = hidden_cluster["client"]
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    path = _textured(client / "slow", np.stack([checker] * 3, axis=-1))
    out = client / "out-slow"
    proc = start_motion("render", path, "-o", out, "--scheduler", hidden_cluster["address"], "--transfer", "ship", "--frames", "0-5", "--chunk-size", "3", "--threads", "1", *SLOW)
    victim = hidden_cluster["workers"]["w2"]
    with Client(hidden_cluster["address"], timeout=10) as c:
        address = next(a for a, w in c.scheduler_info(n_workers=-1)["workers"].items() if w["name"] == "w2")
        wait_for(lambda: any(k.startswith("motion-chunk-") for k in c.processing().get(address, ())), 60, "a chunk on w2")
    kill(victim.pid)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    rep = report(out)
    assert rep["totals"]["rendered"] == 6 and rep["totals"]["failed"] == 0
    assert sum(r["attempts"] > 1 for r in rep["frames"]) == 3, [(r["frame"], r["attempts"], r.get("worker"), r.get("errors") or r.get("error")) for r in rep["frames"]]  # the killed chunk, once more
    assert [f.name for f in frames_in(out)] == [f"scene.{f:04d}.exr" for f in range(6)]
    assert not leftovers(out)  # the client's claims and temporary files are gone


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    """A scheduler and one worker that sees the client's folders, with a cache root of its own."""
    tmp_path = tmp_path_factory.mktemp("warm")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)]
    env = {**os.environ, "MOTION_CACHE_DIR": str(tmp_path / "worker-cache")}
    procs.append(subprocess.Popen([DASK, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard", "--host", "127.0.0.1", "--name", "w"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path, env=env))
    try:
        wait_for(lambda: _try(lambda: _workers_connected(address) == 1), 60, "a dask worker")
        yield {"address": address, "folder": tmp_path, "cache": tmp_path / "worker-cache"}
    finally:
        stop_processes(procs)


def test_a_worker_that_holds_the_scene_is_sent_no_asset_again(one_worker) -> None:
    """A worker warm with the scene (a shared-disk job of it rendered there: its renderer
    holds the scene's meshes and textures in memory) is sent no asset by the ship jobs that
    follow: each reports asset_bytes_to_workers 0, and their frames equal the shared job's.
    Before, the warm worker never checked the assets out (so never kept them), and every ship
    job sent them again (29960 bytes twice in a row)."""
    folder = one_worker["folder"]
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    path = _textured(folder / "shot", np.stack([checker] * 3, axis=-1))
    common = ["--frames", "0-1", "--threads", "1", "--scheduler", one_worker["address"], *TINY]
    shared = motion("render", path, "-o", folder / "shared", "--transfer", "shared", *common)
    assert shared.returncode == 0, shared.stderr
    for run in range(2):
        shipped = motion("render", path, "-o", folder / "ship", "--transfer", "ship", "--overwrite", *common)
        assert shipped.returncode == 0, shipped.stderr
        sent = report(folder / "ship")["executor"]["transfer"]
        assert sent["mode"] == "ship" and sent["assets"] == 2, sent
        assert sent["asset_bytes_to_workers"] == sent["asset_bytes_from_client"] == 0, (run, sent)
        for a, b in zip(frames_in(folder / "ship"), frames_in(folder / "shared")):
            assert np.array_equal(read_frame(a).rgba, read_frame(b).rgba)
