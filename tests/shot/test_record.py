"""The shot record (`.motion-shot.json`) and the farm's claims and run locks, as a hostile
disk holds them: a damaged record is discarded with one warning and written again, a folder
where the record belongs is one located line (exit 2) and is left alone, a claim or lock
naming a pid no process can have is stale; never a traceback, never a hang (a FIFO is never
waited on)."""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from farm_util import frames_in, motion
from motion.pipeline.errors import MotionError
from motion.pipeline.farm import claims
from motion.pipeline.shot.folder_owner import RECORD, check_owner, record_owner, recorded_scene

SCENE = """\
timeline: {fps: 24, first: 0, last: 1}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
lights: [{type: constant, radiance: 0.5}]
render: {resolution: [16, 12], spp: 1, max_depth: 2, shutter_samples: 2, variant: scalar_rgb}
objects:
  - {name: ball, shape: sphere, radius: 0.5}
"""


def _shot(tmp_path: Path) -> tuple[Path, Path]:
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    out.mkdir()
    return scene, out


def _plant(record: Path, kind: str) -> None:
    if kind == "fifo":
        os.mkfifo(record)
    elif kind == "nul":
        record.write_text(json.dumps({"scene": "../s\u0000.yaml"}))
    elif kind == "long":
        record.write_text(json.dumps({"scene": "x" * 5000}))
    elif kind == "deep":
        record.write_text("[" * 100_000)
    elif kind == "huge":
        record.write_bytes(b" " * (1 << 20) + b"{}")
    elif kind == "number":
        record.write_text(json.dumps({"scene": 2**70}))


@pytest.mark.parametrize("kind", ["fifo", "nul"])
def test_a_render_over_a_damaged_record_warns_once_and_rebuilds_it(tmp_path: Path, kind: str) -> None:
    scene, out = _shot(tmp_path)
    _plant(out / RECORD, kind)
    res = motion("render", scene, "-o", out, "--no-progress", timeout=60)  # before: a hang (FIFO), a ValueError traceback (NUL)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    warned = [line for line in res.stderr.splitlines() if RECORD in line]
    assert len(warned) == 1 and "discarded" in warned[0], res.stderr
    assert json.loads((out / RECORD).read_text()) == {"scene": "../s.yaml"}
    assert len(frames_in(out)) == 2


@pytest.mark.parametrize("kind", ["fifo", "nul", "long", "deep", "huge", "number"])
def test_a_damaged_record_is_discarded_with_a_warning(tmp_path: Path, kind: str, caplog: pytest.LogCaptureFixture) -> None:
    scene, out = _shot(tmp_path)
    _plant(out / RECORD, kind)
    assert check_owner(out, scene, overwrite=False) is None  # before: ValueError, OSError, a hang
    assert [r.getMessage() for r in caplog.records if "discarded" in r.getMessage()] != []
    record_owner(out, scene)
    assert json.loads((out / RECORD).read_text()) == {"scene": "../s.yaml"}


def test_a_folder_where_the_record_belongs_is_one_line_and_left_alone(tmp_path: Path) -> None:
    scene, out = _shot(tmp_path)
    (out / RECORD).mkdir()
    (out / RECORD / "notes.txt").write_text("someone's")
    res = motion("render", scene, "-o", out, "--no-progress", timeout=60)
    assert res.returncode == 2, res.stderr  # before: IsADirectoryError traceback after the bake
    assert "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert str(out / RECORD) in res.stderr and "folder" in res.stderr
    assert (out / RECORD / "notes.txt").read_text() == "someone's" and not frames_in(out)


def _claim(path: Path, pid: object, **extra: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"run_id": "other-run", "host": socket.gethostname(), "pid": pid, "time": time.time(), **extra}))


def test_a_claim_and_a_run_lock_naming_pid_2_70_are_stale(tmp_path: Path) -> None:
    scene, out = _shot(tmp_path)
    for name in ("s.0000.exr", "s.0001.exr"):
        _claim(claims.claim_path(out / name), 2**70)
    _claim(out / claims.CLAIM_DIR / "run-other-run.lock", 2**70, scene="other", version="another version")
    res = motion("render", scene, "-o", out, "--no-progress", timeout=60)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr  # before: OverflowError, both frames failed, exit 3
    assert len(frames_in(out)) == 2


@pytest.mark.parametrize("pid", [2**70, 2**31, 1 << 23, 0, -1])
def test_a_pid_no_process_can_have_is_stale_on_any_host(tmp_path: Path, pid: object) -> None:
    for host in (socket.gethostname(), "another-host"):
        path = tmp_path / f"{host}.claim"
        _claim(path, pid, host=host)
        info = claims.read_claim(path)
        assert claims.is_stale(path, info, 3600.0)  # before: OverflowError (2**70); 0, -1, True: alive
        assert not claims._lock_live(path, info)


def test_a_fifo_claim_is_not_waited_on(tmp_path: Path) -> None:
    fifo = tmp_path / "s.0000.exr.claim"
    os.mkfifo(fifo)
    assert claims.read_claim(fifo) == {}  # before: read_bytes waited for a writer
    old = time.time() - 60  # past the write grace: an unreadable claim protects nothing
    os.utime(fifo, (old, old))
    assert claims.is_stale(fifo, {}, 3600.0)


# --- fuzz: whatever the record holds, the owner check ends in a MotionError or goes on ------

JSON = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**80), max_value=2**80) | st.floats() | st.text(max_size=300),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.sampled_from(["scene", "x", ""]) | st.text(max_size=5), inner, max_size=4),
    max_leaves=20,
)
RECORDS = (
    JSON.map(lambda v: json.dumps(v).encode())
    | st.builds(lambda s: json.dumps({"scene": s}).encode(), st.text(max_size=6000))
    | st.builds(lambda n: b"[" * n + b"]" * n, st.integers(0, 200_000))
    | st.binary(max_size=2000)
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=RECORDS)
def test_fuzz_the_shot_record(tmp_path: Path, data: bytes) -> None:
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    (out / RECORD).write_bytes(data)
    try:
        check_owner(out, scene, overwrite=False)
    except MotionError:
        pass  # a record naming another scene file that exists: one line, exit 2
    record_owner(out, scene)
    assert recorded_scene(out) == scene


CLAIMS = st.dictionaries(st.sampled_from(["run_id", "host", "pid", "time", "version", "scene"]), JSON, max_size=6).map(
    lambda d: {**d, "host": socket.gethostname()} if "pid" in d else d
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(info=CLAIMS)
def test_fuzz_claims_and_locks(tmp_path: Path, info: dict) -> None:
    path = tmp_path / "c.claim"
    path.write_text(json.dumps(info))
    read = claims.read_claim(path)
    assert isinstance(claims.is_stale(path, read, 60.0), bool)
    assert isinstance(claims._lock_live(path, read), bool)
