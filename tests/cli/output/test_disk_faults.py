"""Disks that fail (issue 11): a full disk and an output folder that turns read-only in the
middle of a render end the job with one line and exit 4; finished frames stay (and read
back whole), no temporary, zero-byte or claim file is left, no worker is excluded and no
chunk retried for it, the report is written wherever it can be, and a rerun once the disk
is healthy finishes the job.

The disks are real: a tiny tmpfs mounted for the test (`mount -t tmpfs -o size=...`),
which needs root; without it those tests are skipped with the reason. The claim tests
need no privilege.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import time
from pathlib import Path
from typing import Iterator

import pytest

from motion.pipeline.farm.claims import Claimant, claim_path, read_claim, release, try_claim
from motion.pipeline.frame_output import read_frame

from _support import MOTION, REPO, run_motion

SCENE = str(REPO / "tests" / "data" / "farm-tiny.yaml")


def _mount(path: Path, size: str) -> str | None:
    """Mount a tmpfs of `size` at `path`; the reason it cannot, or None."""
    if os.geteuid() != 0:
        return "needs root to mount a tmpfs (the fault is a real full or read-only file system)"
    path.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        return f"cannot mount a tmpfs here: {proc.stderr.strip()}"
    return None


def _remount(path: Path, options: str, busy_retry_s: float = 0.0) -> None:
    """Remount `path` with `options`. The kernel refuses a read-only remount (EBUSY) while a
    file on it is open for writing, as a frame is while a worker writes it: with
    `busy_retry_s` the remount is tried again until the write is over."""
    deadline = time.monotonic() + busy_retry_s
    while True:
        done = subprocess.run(["mount", "-o", f"remount,{options}", str(path)], capture_output=True, text=True)
        if done.returncode == 0:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"mount -o remount,{options} {path}: {done.stderr.strip()}")
        time.sleep(0.005)


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    disk = tmp_path / "disk"
    why = _mount(disk, "24k")
    if why:
        pytest.skip(why)
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def _leftovers(root: Path) -> list[str]:
    """Temporary files, zero-byte files and claims under `root`."""
    bad = []
    for p in root.rglob("*"):
        if p.is_file() and (p.name.endswith(".tmp") or p.stat().st_size == 0 or p.name.endswith(".claim")):
            bad.append(str(p.relative_to(root)))
    return bad


def _report(out: Path, fallback: Path) -> dict:
    paths = [out / "render-report.json"] if (out / "render-report.json").exists() else sorted(fallback.glob("motion-render-report-*.json"))
    assert paths, f"no report in {out} nor in {fallback}"
    return json.loads(paths[-1].read_text())


def _no_blame(report: dict) -> None:
    assert report["disk_fault"]
    assert report["totals"]["retries"] == 0, "a disk fault was retried"
    for w in report["workers"]:
        assert not w["excluded"] and w["failures"] == 0, f"worker blamed for a disk fault: {w}"


def test_full_disk_ends_the_job_cleanly_and_a_rerun_finishes(small_disk: Path, tmp_path: Path) -> None:
    out, spare = small_disk / "out", tmp_path / "spare"
    spare.mkdir()
    args = ["render", SCENE, "--frames", "0-11", "-o", str(out), "--workers", "2", "--chunk-size", "2", "--no-progress"]
    proc = run_motion(*args, env={"TMPDIR": str(spare)}, timeout=240)
    assert proc.returncode == 4, proc.stderr
    assert "Traceback" not in proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("error: disk fault: No space left on device (ENOSPC)"), last
    kept = sorted(out.glob("*.exr"))
    assert 0 < len(kept) < 12, f"expected some frames before the disk filled: {kept}"
    for frame in kept:  # finished frames are whole
        assert read_frame(frame).rgba.shape == (12, 16, 4)
    assert _leftovers(small_disk) == []
    _no_blame(_report(out, spare))

    _remount(small_disk, "size=8m")  # room again: the same command finishes the job
    proc = run_motion(*args, env={"TMPDIR": str(spare)}, timeout=240)
    assert proc.returncode == 0, proc.stderr
    assert len(list(out.glob("*.exr"))) == 12
    assert _leftovers(small_disk) == []


def test_output_turning_read_only_mid_job(small_disk: Path, tmp_path: Path) -> None:
    _remount(small_disk, "size=8m")
    out, spare = small_disk / "out", tmp_path / "spare"
    spare.mkdir()
    args = ["render", SCENE, "--frames", "0-47", "-o", str(out), "--workers", "1", "--chunk-size", "2", "--resolution", "64x48", "--spp", "16", "--no-progress"]
    env = {**os.environ, "TMPDIR": str(spare)}
    proc = subprocess.Popen([MOTION, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    deadline = time.monotonic() + 180
    while not (out / "farm-tiny.0000.exr").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    _remount(small_disk, "ro", busy_retry_s=30)
    try:
        _, stderr = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 4, stderr
    assert "Traceback" not in stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("error: disk fault: Read-only file system (EROFS)"), last
    assert "report " + str(spare) in last, last  # its own folder refused it: written elsewhere
    report = _report(out, spare)
    _no_blame(report)
    assert report["report_fault"]
    for frame in out.glob("*.exr"):
        read_frame(frame)

    _remount(small_disk, "rw")  # a claim left on the read-only disk names a dead process: stale
    # the frames claimed before the disk turned read-only (how far the job got depends on
    # the machine's load): rendering them again takes over their stale claims
    claimed = [int(p.name.split(".")[-3]) for p in (out / ".motion-claims").glob("*.claim")] if (out / ".motion-claims").is_dir() else []
    upto = max([5, *claimed])
    proc2 = run_motion(*args[:3], f"0-{upto}", *args[4:], env={"TMPDIR": str(spare)}, timeout=240)
    assert proc2.returncode == 0, proc2.stderr
    assert [p for p in _leftovers(small_disk) if p.endswith(".claim")] == []


# --- claims: owner recorded, written whole, empty / unreadable / dead-owner claims stale ---


def _aged(path: Path, seconds: float) -> None:
    t = time.time() - seconds
    os.utime(path, (t, t))


def test_claim_records_its_owner_and_is_never_empty(tmp_path: Path) -> None:
    frame = tmp_path / "f.0001.exr"
    ok, _ = try_claim(frame, Claimant.here("run-a"), 60)
    assert ok
    info = read_claim(claim_path(frame))
    assert info["pid"] == os.getpid() and info["host"] == socket.gethostname() and info["run_id"] == "run-a"
    assert [p.name for p in claim_path(frame).parent.iterdir()] == ["f.0001.exr.claim"]  # no temporary left
    ok, holder = try_claim(frame, Claimant("run-b", socket.gethostname(), os.getpid()), 60)
    assert not ok and holder["run_id"] == "run-a"  # a live claim holds
    assert release(frame, "run-a") and not claim_path(frame).exists()


@pytest.mark.parametrize("content", [b"", b"{not json", b"[1, 2]", b"\x00\xff"], ids=["empty", "garbage", "not-an-object", "binary"])
def test_empty_or_unreadable_claims_are_stale(tmp_path: Path, content: bytes) -> None:
    frame = tmp_path / "f.0002.exr"
    cp = claim_path(frame)
    cp.parent.mkdir(parents=True)
    cp.write_bytes(content)
    ok, _ = try_claim(frame, Claimant.here("run-c"), stale_after_s=3600)
    assert not ok, "a fresh empty claim may be mid-write (no hard links): it holds for the grace period"
    _aged(cp, 30)
    ok, _ = try_claim(frame, Claimant.here("run-c"), stale_after_s=3600)
    assert ok, "an empty or unreadable claim past the grace period is stale"
    assert read_claim(cp)["run_id"] == "run-c"


def test_dead_owner_claim_is_stale(tmp_path: Path) -> None:
    frame = tmp_path / "f.0003.exr"
    dead = subprocess.Popen(["true"])
    dead.wait()
    cp = claim_path(frame)
    cp.parent.mkdir(parents=True)
    cp.write_text(json.dumps({"run_id": "gone", "host": socket.gethostname(), "pid": dead.pid, "time": time.time()}))
    ok, _ = try_claim(frame, Claimant.here("run-d"), stale_after_s=3600)
    assert ok


def _fill(disk: Path) -> None:
    """Fill `disk` to its last block (a file `fill` that takes every free byte)."""
    try:
        with open(disk / "fill", "wb") as fh:
            while True:
                fh.write(b"\0" * 1024)
                fh.flush()
    except OSError:
        pass


@pytest.mark.parametrize("command", [
    ["export", "SRC", "-o", "DISK/png"],
    ["export", "SRC", "--format", "jpg", "-o", "DISK/jpg"],
    ["contact-sheet", "SRC", "-o", "DISK/sheet.png"],
    ["view", "SRC", "-o", "DISK/flip/index.html"],
    ["bake", SCENE, "-o", "DISK/motion.json", "--frames", "0-3"],
    ["bake", SCENE, "-o", "DISK/motion.npz", "--frames", "0-3"],
    ["plot", str(REPO / "scenes" / "cannonball.yaml"), "-o", "DISK/plot.png"],
    ["telecine", "SRC", "-o", "DISK/60i"],
    ["telecine", "SRC", "-o", "TMP/60i", "--movie", "DISK/60i.mov"],
])
def test_every_writer_reports_a_full_disk_in_one_line(small_disk: Path, tmp_path: Path, command: list[str]) -> None:
    """Issue 24/26: every writer goes through the one write policy (pipeline/write_policy.py):
    on a full disk `export`, `contact-sheet`, `view` and `bake -o` end with one line and
    exit 4 (tracebacks, exit 1, or exit 2 before), leaving no temporary file; `plot`
    said 'writing ?' and left a partial file (it wrote with savefig in place)."""
    src = tmp_path / "src"
    done = run_motion("render", SCENE, "-o", str(src), "--frames", "0-3", "--resolution", "16x12", "--spp", "1", "--no-progress")
    assert done.returncode == 0, done.stderr
    _fill(small_disk)
    argv = [str(src) if a == "SRC" else a.replace("DISK", str(small_disk)).replace("TMP", str(tmp_path)) for a in command]
    res = run_motion(*argv)
    assert res.returncode == 4, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip() and not line.startswith("motion:")]
    assert len(lines) == 1 and lines[0].startswith("error: disk fault: No space left on device") and "Traceback" not in res.stderr, res.stderr
    assert str(small_disk) in lines[0], res.stderr  # the line names what was being written (a plot said 'writing ?')
    (small_disk / "fill").unlink()
    assert not _leftovers(small_disk), _leftovers(small_disk)


def test_the_writers_inside_a_render_report_a_full_disk_in_one_line(small_disk: Path, tmp_path: Path) -> None:
    """Issue 26: the writers a render calls after its frames, each fed a full disk through
    the write policy: the temporal pass's EXR (it wrote with its own temporary file and
    said nothing of the disk), a frame claim, a deliverable's staging folder; each ends in
    one DiskFaultError line naming the file or folder, and leaves nothing behind. The
    caches whose loss costs only recomputation (the variant probe, the cost history) say
    nothing and leave nothing."""
    from motion.pipeline.errors import DiskFaultError
    from motion.pipeline.write_policy import staging, write_best_effort
    from motion.pipeline.render.output.temporal import process_frame

    src = tmp_path / "src"
    done = run_motion("render", SCENE, "-o", str(src), "--frames", "0-2", "--resolution", "16x12", "--spp", "1", "--no-progress", "--denoise", "--temporal", "reproject")
    assert done.returncode == 0, done.stderr
    frames = sorted(src.glob("*.exr"))
    for f in frames:
        (small_disk / f.name).write_bytes(f.read_bytes())
    _fill(small_disk)
    target = small_disk / frames[1].name
    before = target.read_bytes()
    with pytest.raises(DiskFaultError, match=f"No space left on device.*{target}"):
        process_frame(str(target), [(-1, str(small_disk / frames[0].name)), (1, str(small_disk / frames[2].name))])
    assert target.read_bytes() == before  # the frame is untouched: the new one was never published
    with pytest.raises(DiskFaultError, match="No space left on device.*claiming frame"):
        try_claim(small_disk / "x.0001.exr", Claimant.here("run"), 60.0)
    with pytest.raises(DiskFaultError, match=f"No space left on device.*{small_disk}"):
        with staging(small_disk, "making the 24p deliverable in") as staged:
            (staged / "movie.mov").write_bytes(b"\0" * 65536)
    assert write_best_effort(small_disk / "probe.json", b"{}" * 10000) is False
    (small_disk / "fill").unlink()
    assert not _leftovers(small_disk), _leftovers(small_disk)
    assert sorted(p.name for p in small_disk.iterdir() if p.is_file()) == sorted(f.name for f in frames)


def test_a_full_cache_disk_is_one_line_and_poisons_no_later_run(small_disk: Path, tmp_path: Path) -> None:
    """Issue 24: the asset cache on a full disk. Mitsuba's PLY writer left an empty file
    and said nothing; the empty entry was then a cache hit in every later run (each frame
    failed three times, also after space was freed). Now the write is checked before it is
    published: one line, exit 4, no entry; and once there is room the same command renders."""
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = tmp_path / "s.yaml"
    scene.write_text("timeline: {fps: 24, first: 0, last: 1}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
                     "lights: [{type: constant, radiance: 1}]\nobjects: [{name: m, shape: mesh, file: m.obj}]\nrender: {resolution: [16, 12], spp: 1}\n")
    env = {"MOTION_CACHE_DIR": str(small_disk), "DRJIT_CACHE_DIR": str(tmp_path / "kernels")}
    _fill(small_disk)
    res = run_motion("render", str(scene), "-o", str(tmp_path / "out"), "--no-progress", env=env)
    assert res.returncode == 4, res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "disk fault: No space left on device" in errors[0] and "converted asset" in errors[0], res.stderr
    assert not [p for p in (small_disk / "assets").glob("*") if not p.name.startswith(".")]
    (small_disk / "fill").unlink()
    again = run_motion("render", str(scene), "-o", str(tmp_path / "out"), "--no-progress", env=env)
    assert again.returncode == 0, again.stderr
    assert len(list((tmp_path / "out").glob("*.exr"))) == 2
