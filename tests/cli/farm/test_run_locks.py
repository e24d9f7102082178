"""Run locks (farm/claims.py): renders of one version share an output folder, another version
is refused naming it, and the lock is never written through a link out of the folder."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import time
from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import SCENE, SLOW, TINY, frames_in, leftovers, motion, start_motion, wait_for
from motion.pipeline.errors import OutputInUseError
from motion.pipeline.farm import claims


def _plant_lock(out: Path, pid: int, version: str, run_id: str = "planted-run", at: float | None = None) -> Path:
    folder = out / claims.CLAIM_DIR
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{claims.RUN_LOCK_PREFIX}{run_id}{claims.RUN_LOCK_SUFFIX}"
    t = time.time() if at is None else at
    path.write_text(json.dumps({"run_id": run_id, "host": socket.gethostname(), "pid": pid, "scene": "/farm/other/shot.yaml", "version": version, "time": t}))
    return path


def test_another_version_rendering_into_the_folder_is_refused_naming_it(tmp_path: Path) -> None:
    out = tmp_path / "out"
    # a live run (this test's own process) of another version holds the folder
    _plant_lock(out, os.getpid(), "another-version")
    res = motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY)
    assert res.returncode == 2, res.stderr
    line = res.stderr.strip()
    assert line.count("\n") == 0 and "another version" in line and f"pid {os.getpid()}" in line and socket.gethostname() in line, line
    assert "/farm/other/shot.yaml" in line
    assert not frames_in(out)
    # once that run is gone (its pid no longer lives here), the folder is free again
    dead = subprocess.Popen(["true"])
    dead.wait()
    (out / claims.CLAIM_DIR / "run-planted-run.lock").unlink()
    _plant_lock(out, dead.pid, "another-version", run_id="dead-run")
    res = motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY)
    assert res.returncode == 0, res.stderr
    assert len(frames_in(out)) == 2 and not leftovers(out)


def test_two_versions_at_once_one_goes_on_the_other_refuses(tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = start_motion("render", SCENE, "-o", out, "--frames", "0-7", "--workers", "1", "--chunk-size", "2", *SLOW)
    wait_for(lambda: any((out / claims.CLAIM_DIR).glob("run-*.lock")) if (out / claims.CLAIM_DIR).is_dir() else False, 60, "the first run's lock")
    second = motion("render", SCENE, "-o", out, "--frames", "0-7", "--resolution", "96x72", "--spp", "2", "--no-progress", "--resume")
    assert second.returncode == 2 and "another version" in second.stderr and f"pid {first.pid}" in second.stderr, second.stderr
    _, stderr = first.communicate(timeout=120)
    assert first.returncode == 0, stderr
    assert len(frames_in(out)) == 8 and not leftovers(out)
    assert motion("render", SCENE, "-o", out, "--frames", "0-7", *SLOW, "--check").returncode == 0  # one version only


def test_run_locks_of_one_version_share_and_of_two_give_way_by_order(tmp_path: Path) -> None:
    me = claims.Claimant.here("run-b")
    # the same version (a shard, a second machine helping) shares the folder
    _plant_lock(tmp_path, os.getpid(), "v1", run_id="run-a")
    lock = claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")
    claims.release_run_lock(lock)
    assert not lock.path.exists()
    # two versions that started together: the later lock gives way, the earlier goes on
    later = _plant_lock(tmp_path, os.getpid(), "v2", run_id="run-c", at=time.time() + 60)
    lock = claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")  # run-a is v1; run-c is later
    claims.release_run_lock(lock)
    later.unlink()
    _plant_lock(tmp_path, os.getpid(), "v2", run_id="run-d", at=time.time() - 1)
    with pytest.raises(OutputInUseError):
        claims.take_run_lock(tmp_path, me, "shot.yaml", "v1")
    assert not (tmp_path / claims.CLAIM_DIR / "run-run-b.lock").exists()  # the refused run leaves no lock
    # garbage in a lock file (not JSON, wrong types) is no lock, once past the write grace
    junk = tmp_path / claims.CLAIM_DIR / "run-junk.lock"
    for body in (b"\xff\xfe", b"[1,2]", b'{"run_id": 5, "pid": "x"}', b'{"run_id": "r", "pid": true}'):
        junk.write_bytes(body)
        old = time.time() - 60
        os.utime(junk, (old, old))
        (tmp_path / claims.CLAIM_DIR / "run-run-d.lock").unlink(missing_ok=True)
        claims.release_run_lock(claims.take_run_lock(tmp_path, me, "shot.yaml", "v1"))
        assert not junk.exists()


def test_the_run_lock_is_never_written_through_a_link_out_of_the_output_folder(tmp_path: Path) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(BASE + "output: {filename: 'sub/{name}.####.exr'}\n")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / claims.CLAIM_DIR).symlink_to(tmp_path / "elsewhere")
    res = motion("render", scene, "-o", tmp_path / "out")
    assert res.returncode == 2 and "outside the output folder" in res.stderr, res.stderr
    assert not os.listdir(tmp_path / "elsewhere") and not frames_in(tmp_path / "out" / "sub")
