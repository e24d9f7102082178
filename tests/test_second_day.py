"""A user's second day (issue 23): what a user does twice, not once. Reruns that just work,
deliverables made from the frames the run selected and rebuilt only when those change,
stale frames named, a dry run that shows the resolved settings and the job's cost, status
like Blender's, and a scheduler that cannot be reached found in seconds."""

from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import av
import pytest
import yaml

from farm_util import MOTION, ROOT, SCENE, TINY, frames_in, motion, report
from motion.pipeline.farm.progress import Progress

LINES = [a for a in TINY if a != "--no-progress"]  # stderr is not a terminal: plain progress lines


def _movie_frames(path: Path) -> int:
    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0))


def test_the_same_command_twice_renders_and_rebuilds_nothing(tmp_path: Path) -> None:
    """The second run of a render with deliverables exits 0, renders nothing and rebuilds
    nothing (it failed with '60i already holds 8 frames; use --overwrite' before);
    --overwrite re-renders the frames, which hold the same pixels, so no deliverable gets a
    new version (versions are keyed on pixels, docs/telecine.md); the report keeps the
    folder's record."""
    out = tmp_path / "out"
    args = ["render", SCENE, "-o", out, "--frames", "0-5", *TINY, "--deliver", "24p,60i,contact", "--deliver-frames", "0-5"]
    first = motion(*args)
    assert first.returncode == 0, first.stderr
    movie = out / "deliver" / "farm-tiny_24p_0-5_v001.mov"
    made = {p.name: p.stat().st_mtime_ns for p in (out / "deliver").rglob("*") if p.is_file()}
    second = motion(*args)
    assert second.returncode == 0, second.stderr
    assert "0 rendered, 6 skipped" in second.stderr
    assert second.stderr.count("up to date") == 3, second.stderr
    assert {p.name: p.stat().st_mtime_ns for p in (out / "deliver").rglob("*") if p.is_file()} == made
    rep = report(out)
    assert rep["deliverables"]["status"] == {"24p": "up to date", "60i": "up to date", "contact": "up to date"}
    # a run that rendered nothing keeps the record of the frames in the folder
    assert rep["folder"]["complete"] == "0-5" and len(rep["history"]) == 1
    assert all(r["status"] == "skipped" and r["rendered_in_run"] == rep["history"][0]["run_id"] and "render_s" in r for r in rep["frames"])
    again = motion(*args, "--overwrite")
    assert again.returncode == 0, again.stderr  # (the 60i folder is not refused)
    assert "6 rendered" in again.stderr
    assert report(out)["deliverables"]["status"] == {"24p": "up to date", "60i": "up to date", "contact": "up to date"}
    assert movie.stat().st_mtime_ns == made[movie.name] and not (out / "deliver" / "farm-tiny_24p_0-5_v002.mov").exists()
    assert not [p for p in (out / "deliver").iterdir() if p.name.startswith(".")]  # no staging left


def test_a_rerun_clears_the_stale_claim_a_stopped_run_left_on_a_complete_frame(tmp_path: Path) -> None:
    """A run stopped between publishing a frame and releasing its claim (the disk turned
    read-only, a kill) leaves a claim on a complete frame. The rerun keeps the frame and
    renders no task for it, so no task cleared the claim: it stayed for good (seen once in
    test_disk_faults). The rerun now removes it; a live claim (another run's, its process
    alive) on a complete frame is left alone."""
    from motion.pipeline.farm.claims import Claimant, claim_path, try_claim

    out = tmp_path / "out"
    args = ["render", SCENE, "-o", out, "--frames", "0-3", *TINY]
    assert motion(*args).returncode == 0
    frames = sorted(out.glob("*.exr"))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True).stdout.strip()
    assert try_claim(frames[1], Claimant(run_id="stopped-run", host=Claimant.here("x").host, pid=int(dead)), 60)[0]
    assert try_claim(frames[2], Claimant.here("live-run"), 60)[0]
    second = motion(*args)
    assert second.returncode == 0, second.stderr
    assert "0 rendered, 4 skipped" in second.stderr
    assert not claim_path(frames[1]).exists()
    assert claim_path(frames[2]).exists()


def test_a_deliverable_is_made_from_the_selected_frames_and_rebuilt_when_they_change(tmp_path: Path) -> None:
    """`--frames 2-5 --deliver 24p --deliver-frames 2-5` in a folder of frames 0-7: the movie
    holds the 4 frames asked for (it held all 8 before); re-rendering them makes a new version."""
    out = tmp_path / "out"
    assert motion("render", SCENE, "-o", out, "--frames", "0-7", *TINY).returncode == 0
    res = motion("render", SCENE, "-o", out, "--frames", "2-5", *TINY, "--deliver", "24p", "--deliver-frames", "2-5")
    assert res.returncode == 0, res.stderr
    movie = out / "deliver" / "farm-tiny_24p_2-5_v001.mov"
    assert _movie_frames(movie) == 4
    assert json.loads((out / "deliver" / "manifest.json").read_text())["deliverables"]["24p@2-5"]["versions"]["v001"]["frames"] == "2-5"
    res = motion("render", SCENE, "-o", out, "--frames", "2-5", "--resolution", "16x12", "--spp", "2", "--no-progress", "--deliver", "24p", "--deliver-frames", "2-5")
    assert res.returncode == 0, res.stderr
    assert "frames 2-5 exist but were made with other settings (spp 1 -> 2): they will be replaced" in res.stderr
    assert report(out)["deliverables"]["status"] == {"24p": "made"}


def test_stale_frames_are_named_by_the_dry_run_and_the_run(tmp_path: Path) -> None:
    """A preview, then `--spp 2 --frames 0-1` into the same folder: the dry run and the run
    say which frames are replaced and which setting differs (replaced without a word before)."""
    out = tmp_path / "out"
    scene = tmp_path / "farm-tiny.yaml"  # a copy, edited below (another file is another shot: shot/identity.py)
    scene.write_text(SCENE.read_text())
    assert motion("render", scene, "-o", out, "--frames", "0-3", *TINY).returncode == 0
    dry = motion("render", scene, "-o", out, "--frames", "0-1", "--resolution", "16x12", "--spp", "2", "--dry-run", "--json")
    assert dry.returncode == 0, dry.stderr
    plan = json.loads(dry.stdout)
    assert plan["replace"] == [{"frames": "0,1", "reason": "were made with other settings (spp 1 -> 2)"}]
    run = motion("render", scene, "-o", out, "--frames", "0-1", "--resolution", "16x12", "--spp", "2", "--no-progress")
    assert run.returncode == 0 and "frames 0,1 exist but were made with other settings (spp 1 -> 2)" in run.stderr, run.stderr
    assert report(out)["replaced"] == [{"frame": f, "reason": "were made with other settings (spp 1 -> 2)"} for f in (0, 1)]
    # the scene edited (not its render settings): named as such
    doc = yaml.safe_load(SCENE.read_text())
    doc["materials"][0]["color"] = [0.1, 0.7, 0.2]
    scene.write_text(yaml.safe_dump(doc))
    dry = motion("render", scene, "-o", out, "--frames", "2-3", *TINY, "--dry-run", "--json")
    assert json.loads(dry.stdout)["replace"] == [{"frames": "2,3", "reason": "were made from another version of the scene (material ball changed)"}]


def test_a_texture_edited_under_the_same_name_makes_its_frames_stale_and_is_named(tmp_path: Path) -> None:
    """The artist repaints tex.ppm and renders again: the frames are replaced and the run
    names the file (before, the settings hash read the scene's text only, so --resume kept
    every old frame). A file added to the scene is an edit of the scene. The header keeps
    each named file's digest (`motion:files`)."""
    from motion.pipeline.frame_output import read_header

    shot = tmp_path / "shot"
    shot.mkdir()
    (shot / "tex.ppm").write_bytes(b"P6 2 2 255\n" + bytes([200, 10, 10] * 4))
    (shot / "s.yaml").write_text(
        "timeline: {fps: 24, first: 0, last: 3}\n"
        "camera: {position: [0, 1, 4], look_at: [0, 0, 0]}\n"
        "lights: [{type: constant, radiance: 1.0}]\n"
        "materials: [{name: m, type: diffuse, color: {file: tex.ppm}}]\n"
        "objects: [{name: s, shape: sphere, material: m}]\n"
    )
    out = tmp_path / "out"
    assert motion("render", shot / "s.yaml", "-o", out, *TINY).returncode == 0
    assert json.loads(read_header(out / "s.0000.exr")["motion:files"]).keys() == {"tex.ppm"}
    again = motion("render", shot / "s.yaml", "-o", out, *TINY)
    assert again.returncode == 0 and report(out)["totals"]["skipped"] == 4  # unchanged: kept
    (shot / "tex.ppm").write_bytes(b"P6 2 2 255\n" + bytes([10, 10, 200] * 4))
    dry = motion("render", shot / "s.yaml", "-o", out, *TINY, "--dry-run", "--json")
    assert json.loads(dry.stdout)["replace"] == [{"frames": "0-3", "reason": "were made from other files (tex.ppm changed)"}], dry.stdout
    run = motion("render", shot / "s.yaml", "-o", out, *TINY)
    assert run.returncode == 0 and "frames 0-3 exist but were made from other files (tex.ppm changed)" in run.stderr, run.stderr
    assert report(out)["totals"]["rendered"] == 4
    (shot / "glow.ppm").write_bytes(b"P6 1 1 255\n" + bytes([9, 9, 9]))
    (shot / "s.yaml").write_text((shot / "s.yaml").read_text().replace("material: m}", "material: m, emission: {radiance: {file: glow.ppm}}}"))
    dry = motion("render", shot / "s.yaml", "-o", out, *TINY, "--dry-run", "--json")
    assert json.loads(dry.stdout)["replace"] == [{"frames": "0-3", "reason": "were made from another version of the scene (object s changed)"}], dry.stdout


def test_the_dry_run_shows_resolved_settings_with_their_source_and_an_estimate(tmp_path: Path) -> None:
    res = motion("render", SCENE, "-o", tmp_path / "out", "--preset", "ci-smoke", "--spp", "3", "--frames", "0-3", "--dry-run", "--json")
    assert res.returncode == 0, res.stderr
    plan = json.loads(res.stdout)
    s = plan["settings"]
    assert s["spp"] == {"value": 3, "from": "flag"}
    assert s["resolution"] == {"value": [64, 36], "from": "preset ci-smoke"}
    assert s["max_depth"]["from"] == "preset ci-smoke" and s["motion_blur"]["from"] == "default"
    assert plan["estimate"]["seconds"] > 0 and plan["estimate"]["basis"]
    text = motion("render", SCENE, "-o", tmp_path / "out", "--preset", "final", "--frames", "0-3", "--dry-run").stdout
    assert "resolution 1920x1080 (preset final)" in text and "estimate:" in text


def test_verbose_says_each_frame_path_and_time_and_no_progress_is_quiet(tmp_path: Path) -> None:
    out = tmp_path / "v"
    res = motion("-v", "render", SCENE, "-o", out, "--frames", "0-2", *LINES, "--workers", "1")
    assert res.returncode == 0, res.stderr
    for f in range(3):
        path = out / f"farm-tiny.{f:04d}.exr"
        assert any(line.startswith(f"  frame {f}: {path} in ") for line in res.stderr.splitlines()), res.stderr
    quiet = motion("render", SCENE, "-o", tmp_path / "q", "--frames", "0-5", *TINY, "--workers", "1")
    assert quiet.returncode == 0, quiet.stderr
    lines = quiet.stderr.splitlines()
    assert not [line for line in lines if "frames/min, 0 failed" in line and "rendered" not in line], lines  # no periodic lines
    assert not [line for line in lines if "bake:" in line or "executor:" in line], lines
    assert any("6 rendered, 0 skipped" in line for line in lines)


def test_the_eta_is_measured_from_the_first_frame_done(monkeypatch: pytest.MonkeyPatch) -> None:
    """Start-up and cold frames do not inflate the ETA: 10 frames, the first done at 5 s
    (cold), then one every 0.5 s: the ETA after 3 frames is 7 x 0.5 s, not 7 x 5/3 s."""
    clock = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    p = Progress(total=10, stream=io.StringIO(), live=False, estimate_s=0.6)
    assert p.eta_s == pytest.approx(6.0)  # the plan's estimate before two frames are done
    for frame, t in ((0, 105.0), (1, 105.5), (2, 106.0)):
        clock[0] = t
        p.event("written", {"frame": frame, "worker": "w", "seconds": 0.5, "path": f"f{frame}"})
    assert p.eta_s == pytest.approx(3.5)


def test_a_healthy_bar_is_green(tmp_path: Path) -> None:
    logging.getLogger("motion").setLevel(logging.INFO)
    with Progress(total=2, stream=io.StringIO(), live=True) as p:
        assert p._bar.columns[1].complete_style == "green"
        p.event("failed", {"frame": 0, "error": "x"})
        assert p._bar.columns[1].complete_style == "red"


@pytest.mark.parametrize("address,says", [
    ("garbage://host:1", "unknown scheme 'garbage'"),
    ("localhost:abc", "expected tcp://HOST:PORT"),
    ("127.0.0.1:1", "cannot reach 127.0.0.1:1: Connection refused"),
    ("SCHEDFILE", "not a Dask scheduler file (not JSON"),
])
def test_an_unreachable_scheduler_is_found_in_seconds_before_the_bake(tmp_path: Path, address: str, says: str) -> None:
    if address == "SCHEDFILE":
        address = str(tmp_path / "scheduler.json")
        Path(address).write_text("not json")
    for extra in ([], ["--dry-run"]):
        t0 = time.monotonic()
        res = motion("render", SCENE, "-o", tmp_path / "out", "--scheduler", address, *TINY, *extra)
        assert time.monotonic() - t0 < 10
        assert res.returncode == 2 and says in res.stderr, res.stderr
        assert "bake:" not in res.stderr and "Traceback" not in res.stderr


def test_a_server_that_is_not_dask_is_refused_in_seconds(tmp_path: Path) -> None:
    import socket
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    port = server.getsockname()[1]

    def speak() -> None:  # a server that greets every connection with 4 MB of noise
        for _ in range(2):
            conn, _ = server.accept()
            try:
                conn.sendall(b"\xff" * (4 << 20))
            except OSError:
                pass
            conn.close()

    threading.Thread(target=speak, daemon=True).start()
    t0 = time.monotonic()
    res = motion("render", SCENE, "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}", *TINY)
    assert time.monotonic() - t0 < 10
    assert res.returncode == 2 and "answers, but not as a Dask scheduler" in res.stderr, res.stderr
    server.close()


def test_a_preset_spread_makes_what_it_can_of_the_scenes_deliverables(tmp_path: Path) -> None:
    """The scene asks for 24p, 60i and a contact sheet (output.deliver); the ci-smoke
    preset spreads 3 frames over the shot: the run exits 0, makes the contact sheet and
    says why the movies are left out (exit 2 before: '--deliver needs a gapless run')."""
    doc = yaml.safe_load(SCENE.read_text())
    doc.setdefault("output", {})["deliver"] = ["24p", "60i", "contact"]
    scene = tmp_path / "farm-tiny.yaml"
    scene.write_text(yaml.safe_dump(doc))
    res = motion("render", scene, "-o", tmp_path / "out", "--preset", "ci-smoke", "--no-progress")
    assert res.returncode == 0, res.stderr
    assert "24p: not made: the shot (frames 0-47) lacks frames 1-23,25-46" in res.stderr
    assert (tmp_path / "out" / "deliver" / "farm-tiny_contact_v001.png").is_file()
    assert not list((tmp_path / "out" / "deliver").glob("farm-tiny_24p*"))
    part = motion("render", scene, "-o", tmp_path / "full", "--frames", "0-3", "--deliver-frames", "0-3", *TINY)
    assert part.returncode == 0 and (tmp_path / "full" / "deliver" / "farm-tiny_24p_0-3_v001.mov").is_file(), part.stderr


@pytest.mark.render
def test_make_render_twice_with_the_readmes_smoke_args(tmp_path: Path) -> None:
    """The README's `make render ARGS="--preset ci-smoke -o DIR"`, twice: both exit 0, the
    second renders nothing, and the paths printed are the true ones under DIR (before:
    exit 2 on the gaps, then paths under out/cannonball-splash echoed anyway)."""
    out = tmp_path / "smoke"
    env = {**os.environ, "MAKEFLAGS": ""}
    cmd = ["make", "-s", "-C", str(ROOT), "render", f"ARGS=--preset ci-smoke --resolution 32x18 --spp 1 -o {out} --no-progress"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert first.returncode == 0, first.stdout + first.stderr
    assert len(frames_in(out)) == 3
    assert f"frames: {out}/cannonball-splash.0000.exr" in first.stderr
    assert "out/cannonball-splash" not in (first.stdout + first.stderr).replace(str(out), "")
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert second.returncode == 0, second.stdout + second.stderr
    assert "0 rendered, 3 skipped" in second.stderr and "contact: up to date" in second.stderr


def test_view_open_on_a_headless_machine_says_so(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert motion("render", SCENE, "-o", out, "--frames", "0-1", *TINY).returncode == 0
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "BROWSER")}
    res = subprocess.run([MOTION, "view", str(out), "--open"],
                         capture_output=True, text=True, env={**env, "PATH": "/usr/bin:/bin"}, timeout=120)
    assert res.returncode == 2 and "no web browser can be started here" in res.stderr, res.stderr
    assert (out / "flipbook" / "index.html").is_file()


# --- small jobs at the engine's start-up cost (issue 28) -------------------------------------


def _auto(env_extra: dict[str, str] | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "MOTION_EXECUTOR"}
    return {**env, **(env_extra or {})}


def test_a_small_job_renders_inline_and_a_large_one_on_workers(tmp_path: Path) -> None:
    """The executor is chosen by the frames' estimated cost: 3 tiny frames render in this
    process (no worker spawned), a job estimated at minutes spreads over worker processes,
    and --workers always means processes."""
    from motion.pipeline.shot.render import choose_inline
    from motion.pipeline.shot.request import RenderRequest

    small = {"warm_frame_s": 0.05, "cold_extra_s": 1.0}
    large = {"warm_frame_s": 2.0, "cold_extra_s": 1.0}
    req = RenderRequest(scene=SCENE)
    env = _auto()
    old = os.environ.pop("MOTION_EXECUTOR", None)
    try:
        assert choose_inline(req, small, [0, 1, 2]) and not choose_inline(req, large, list(range(24)))
        assert not choose_inline(RenderRequest(scene=SCENE, workers=2), small, [0, 1, 2])
        assert not choose_inline(RenderRequest(scene=SCENE, scheduler="tcp://x:1"), small, [0, 1, 2])
    finally:
        if old is not None:
            os.environ["MOTION_EXECUTOR"] = old
    res = subprocess.run([MOTION, "render", str(SCENE), "-o", str(tmp_path / "out"), "--frames", "0-2", *TINY], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    rep = report(tmp_path / "out")
    assert rep["executor"]["kind"] == "inline" and len({r["worker"] for r in rep["frames"]}) == 1


def test_cache_warm_makes_a_ci_jobs_first_frame_warm(tmp_path: Path) -> None:
    """`motion cache warm SCENE --preset P` compiles the job's kernels into a fresh cache;
    the job then compiles none; `motion cache key` names what the cache depends on."""
    env = _auto({"MOTION_CACHE_DIR": str(tmp_path / "cache"), "DRJIT_CACHE_DIR": str(tmp_path / "cache" / "kernels")})
    key = subprocess.run([MOTION, "cache", "key"], capture_output=True, text=True, env=env, timeout=60)
    assert key.returncode == 0 and key.stdout.startswith("motion-kernels-") and str(tmp_path / "cache" / "kernels") in key.stdout
    warm = subprocess.run([MOTION, "cache", "warm", str(SCENE), "--preset", "ci-smoke"], capture_output=True, text=True, env=env, timeout=300)
    assert warm.returncode == 0, warm.stderr
    assert "motion-warm-" not in warm.stdout + warm.stderr  # no path in the folder it removes
    compiled = int(warm.stdout.split("kernels: ")[1].split()[0])
    assert compiled > 0, warm.stdout
    job = subprocess.run([MOTION, "render", str(SCENE), "--preset", "ci-smoke", "-o", str(tmp_path / "out"), "--no-progress"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert job.returncode == 0, job.stderr
    rows = report(tmp_path / "out")["frames"]
    assert sum(int(r.get("kernels_compiled") or 0) for r in rows) == 0, [(r["frame"], r.get("worker"), r.get("cold"), r.get("kernels_compiled")) for r in rows]


# --- deliverables a studio accepts --------------------------------------------------------


@pytest.fixture(scope="module")
def shot_1001(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess]:
    """A shot numbered 1001-1006 at 24 fps rendered with 24p, 60i and a contact sheet."""
    folder = tmp_path_factory.mktemp("tc")
    scene = folder / "tc.yaml"
    scene.write_text("timeline: {fps: 24, first: 1001, last: 1006}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
                     "lights: [{type: constant, radiance: 1}]\nobjects: [{name: b, shape: sphere, radius: 0.5}]\nrender: {resolution: [16, 12], spp: 1}\n")
    res = motion("render", scene, "-o", folder / "out", "--deliver", "24p,60i,contact", "--no-progress")
    assert res.returncode == 0, res.stderr
    return folder / "out", res


def test_timecode_comes_from_the_frame_number_and_the_rate_is_named(shot_1001: tuple[Path, subprocess.CompletedProcess]) -> None:
    """A shot numbered 1001-1006 at 24 fps: frame 1001's timecode is 00:00:41:17 in its EXR
    and its 24p movie (it was 00:00:00:00); the 24p movie plays at 23.976 and says so."""
    from motion.pipeline.frame_output import read_header, timecode_str

    out, res = shot_1001
    assert timecode_str(read_header(out / "tc.1001.exr")["timeCode"]) == "00:00:41:17"
    with av.open(str(out / "deliver" / "tc_24p_v001.mov")) as c:
        assert c.streams.video[0].metadata.get("timecode") == "00:00:41:17"
    assert "tc_24p_v001.mov (23.976 fps (24000/1001))" in res.stderr
    assert "tc_60i_v001.mov (29.97 fps (30000/1001) interlaced, 2 fields a frame)" in res.stderr
    made = json.loads((out / "deliver" / "manifest.json").read_text())["deliverables"]
    assert made["24p"]["versions"]["v001"]["outputs"][0]["rate"] == "23.976 fps (24000/1001)"


def test_movies_flipbook_sheet_and_report_name_the_rate_and_the_frames_timecode(shot_1001: tuple[Path, subprocess.CompletedProcess]) -> None:
    """Wherever else the rate or the timecode is shown it agrees with the frames and the
    movies: the flipbook of frames 1001.. says 00:00:41:17 (it counted from the folder's
    first frame: 00:00:00:00) and of their 60i pulldown 00:00:41:21, as that movie's
    timecode does; the flipbook and the contact sheet name 29.97 fps (30000/1001) (they
    said '30000/1001 fps'); each movie's comment names its rate, scan and view; the report
    gives each movie's rate as the manifest does."""
    from motion.pipeline.telecine.contact_sheet import sheet_layout
    from motion.pipeline.telecine.sequence import discover

    out, _ = shot_1001
    interlaced = out / "deliver" / "60i_v001"
    with av.open(str(out / "deliver" / "tc_60i_v001.mov")) as c:
        assert c.streams.video[0].metadata.get("timecode") == "00:00:41:21"
        assert c.metadata.get("comment", "").startswith("29.97 fps (30000/1001), interlaced tff; view: OCIO")
    with av.open(str(out / "deliver" / "tc_24p_v001.mov")) as c:
        assert c.metadata.get("comment", "").startswith("23.976 fps (24000/1001), progressive; view: OCIO")
    for folder, first, rate in ((out, "00:00:41:17", "24 fps"), (interlaced, "00:00:41:21", "29.97 fps (30000/1001)")):
        res = motion("view", folder)
        assert res.returncode == 0, res.stderr
        page = (folder / "flipbook" / "index.html").read_text()
        data = json.loads(page.split('id="flipbook-data" type="application/json">', 1)[1].split("</script>", 1)[0])
        assert data["frames"][0]["frame"] == 1001 and data["frames"][0]["timecode"] == first
        assert data["fps_text"] == rate
    assert sheet_layout(discover(interlaced)).header.endswith("  29.97 fps (30000/1001)")
    rates = report(out)["deliverables"]["rates"]
    assert rates == {str(out / "deliver" / "tc_24p_v001.mov"): "23.976 fps (24000/1001)",
                     str(out / "deliver" / "tc_60i_v001.mov"): "29.97 fps (30000/1001) interlaced, 2 fields a frame"}


def test_the_default_view_keeps_a_bright_sky_from_clipping() -> None:
    """The deliverables' default view is OCIO's ACES 2.0 SDR (a tone curve): an HDR sky of
    1.5-6 scene-linear clips under 1% of its pixels (the plain sRGB curve clipped them all)."""
    import numpy as np

    from motion.pipeline.telecine.movie import ViewTransform

    sky = np.ones((64, 64, 4), np.float32)
    sky[..., 0], sky[..., 1], sky[..., 2] = np.linspace(1.5, 4.0, 64)[:, None], np.linspace(2.0, 5.0, 64)[:, None], np.linspace(3.0, 6.0, 64)[:, None]
    clipped = lambda view: float((view.encode(sky) >= 1.0 - 1e-6).any(axis=-1).mean())  # noqa: E731
    assert clipped(ViewTransform()) < 0.01
    assert clipped(ViewTransform(ocio_config="none")) == 1.0
    assert "ACES 2.0" in ViewTransform().description
