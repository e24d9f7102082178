"""The local executor with real processes: a worker SIGKILLed mid-job, frames that fail
everywhere (exit 3), task timeouts, Ctrl-C then resume (a truncated EXR is re-rendered),
two renders into one folder at once, and no drjit in the main process."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from farm_util import MOTION, SCENE, SLOW, TINY, frames_in, kill, leftovers, motion, report, start_motion, wait_for, worker_pids
from motion.pipeline.frame_output import is_complete, read_frame

pytestmark = pytest.mark.render


def _valid(folder: Path, frames: range) -> None:
    for f in frames:
        fr = read_frame(folder / f"farm-tiny.{f:04d}.exr")
        assert fr.meta["frame"] == f


def test_sigkill_a_worker_mid_job(tmp_path) -> None:
    out = tmp_path / "out"
    proc = start_motion("render", SCENE, "-o", out, "--frames", "0-15", "--workers", "2", "--chunk-size", "4", *SLOW)
    wait_for(lambda: len(worker_pids(proc.pid)) == 2, 30, "two workers")
    wait_for(lambda: len(frames_in(out)) >= 2, 60, "first frames")
    victim = worker_pids(proc.pid)[0]
    kill(victim)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    _valid(out, range(16))
    rep = report(out)
    assert rep["totals"]["rendered"] + rep["totals"]["skipped"] == 16 and rep["totals"]["failed"] == 0
    lost = [w for w in rep["workers"] if w["lost"]]
    assert len(lost) == 1 and lost[0]["worker"].endswith(f":{victim}") and "signal 9" in lost[0]["lost"][0]
    # only the killed chunk was retried; each of its frames was attempted at most twice and
    # rendered once (frames written before the kill are found complete on the retry)
    retried = [r for r in rep["frames"] if r["attempts"] > 1]
    assert 1 <= len(retried) <= 4 and all(r["attempts"] == 2 for r in retried)
    retried_frames = [r["frame"] for r in retried]
    assert retried_frames == list(range(retried_frames[0], retried_frames[0] + len(retried_frames)))
    assert all(r["attempts"] == 1 for r in rep["frames"] if r["frame"] not in retried_frames)
    assert not leftovers(out)


def test_frames_failing_everywhere_exit_3_others_finish(tmp_path) -> None:
    out = tmp_path / "out"
    (out / "farm-tiny.0002.exr").mkdir(parents=True)  # frame 2 cannot be written, anywhere
    # 4 attempts: the (one) worker fails 3 times (max_worker_failures), is excluded and replaced
    res = motion("render", SCENE, "-o", out, "--frames", "0-4", "--retries", "3", "--workers", "1", *TINY)
    assert res.returncode == 3, res.stderr
    assert "1 of 5 frames failed everywhere" in res.stderr and "frame 2:" in res.stderr
    _valid(out, [0, 1, 3, 4])
    rep = report(out)
    assert rep["failed"] == [{"frame": 2, "error": rep["failed"][0]["error"], "attempts": 4}]
    assert "Error" in rep["failed"][0]["error"]
    assert rep["totals"]["rendered"] == 4
    excluded = [w for w in rep["workers"] if w["excluded"]]
    assert len(excluded) == 1 and excluded[0]["failures"] == 3 and "excluded for this job" in res.stderr
    assert len(rep["workers"]) == 2  # the replacement made the 4th attempt
    assert not leftovers(out)


def test_task_timeout_cancels_and_retries(tmp_path) -> None:
    out = tmp_path / "out"
    # a frame at these settings takes far longer than 0.2 s (worker start-up included)
    res = motion("render", SCENE, "-o", out, "--frames", "0", "--task-timeout", "0.2", "--retries", "1", *SLOW)
    assert res.returncode == 3, res.stderr
    rep = report(out)
    assert rep["failed"][0]["attempts"] == 2 and "timed out after 0.2s" in rep["failed"][0]["error"]
    assert not frames_in(out) and not leftovers(out)


def test_ctrl_c_then_resume_renders_only_what_is_missing(tmp_path) -> None:
    out = tmp_path / "out"
    args = ("render", SCENE, "-o", out, "--frames", "0-13", "--workers", "1", "--chunk-size", "2", *SLOW)
    proc = start_motion(*args)
    wait_for(lambda: len(frames_in(out)) >= 3, 60, "some frames")
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    done = frames_in(out)
    assert 3 <= len(done) < 14
    assert all(is_complete(p) for p in done)  # finished frames stay, whole
    assert not leftovers(out)  # no partial files, no claims
    assert report(out)["interrupted"] is True
    # a frame truncated on disk (a copy interrupted, a full disk) is detected and redone
    victim = done[1]
    victim.write_bytes(victim.read_bytes()[:200])
    kept = {p.name for p in done} - {victim.name}
    res = motion(*args)
    assert res.returncode == 0, res.stderr
    rep = report(out)
    rendered = {f"farm-tiny.{r['frame']:04d}.exr" for r in rep["frames"] if r["status"] == "rendered"}
    skipped = {f"farm-tiny.{r['frame']:04d}.exr" for r in rep["frames"] if r["status"] == "skipped"}
    assert skipped == kept and victim.name in rendered and len(rendered) == 14 - len(kept)
    _valid(out, range(14))
    # and --overwrite re-renders everything
    res = motion(*args[:-len(SLOW)], *TINY, "--overwrite")
    assert res.returncode == 0 and report(out)["totals"]["rendered"] == 14


def test_two_renders_into_one_folder_never_render_a_frame_twice(tmp_path) -> None:
    out = tmp_path / "out"
    args = ("render", SCENE, "-o", out, "--frames", "0-11", "--workers", "1", "--chunk-size", "3", *SLOW)
    a = start_motion(*args, "--report", tmp_path / "a.json")
    b = start_motion(*args, "--report", tmp_path / "b.json")
    for p in (a, b):
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    import json

    reps = [json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json")]
    rendered = Counter(r["frame"] for rep in reps for r in rep["frames"] if r["status"] == "rendered")
    assert sorted(rendered) == list(range(12)) and set(rendered.values()) == {1}
    assert all(rep["totals"]["rendered"] > 0 for rep in reps), "the renders did not overlap"
    _valid(out, range(12))
    assert not leftovers(out)


def test_main_process_never_imports_drjit(tmp_path) -> None:
    code = (
        "import sys; from pathlib import Path\n"
        "from motion.pipeline.shot import RenderRequest, run_render\n"
        f"rep = run_render(RenderRequest(scene=Path({str(SCENE)!r}), output_dir=Path({str(tmp_path)!r}), frames_spec='0-3', "
        "workers=2, render_overrides={'resolution': (16, 12), 'spp': 1}, progress=False))\n"
        "assert rep['totals']['rendered'] == 4, rep['totals']\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('drjit', 'mitsuba')]\n"
        "assert not bad, bad\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_motion_file_from_bake_matches_baking_here(tmp_path) -> None:
    out = tmp_path / "out"
    for ext in ("json", "npz"):
        res = subprocess.run([MOTION, "bake", str(SCENE), "-o", str(tmp_path / f"m.{ext}"), "--frames", "0-5"], capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
    res = motion("render", SCENE, "-o", out, "--frames", "0-3", "--motion", tmp_path / "m.json", *TINY)
    assert res.returncode == 0, res.stderr
    assert report(out)["totals"]["rendered"] == 4
    # the same motion from the .npz and from baking here: every frame is already complete
    for extra in (["--motion", tmp_path / "m.npz"], []):
        res = motion("render", SCENE, "-o", out, "--frames", "0-3", *extra, *TINY)
        assert res.returncode == 0, res.stderr
        assert report(out)["totals"]["skipped"] == 4
    res = motion("render", SCENE, "-o", out, "--frames", "0-9", "--motion", tmp_path / "m.json", *TINY)
    assert res.returncode == 2 and "frames 6-9 are not in the baked file" in res.stderr
    res = motion("render", SCENE, "-o", out, "--frames", "0-3", "--motion", tmp_path / "m.json", "--preset", "ci-smoke")
    assert res.returncode == 2 and "shutter samples" in res.stderr
