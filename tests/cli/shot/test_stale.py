"""Stale frames (shot/stale.py) as a user meets them: the same command twice renders and
rebuilds nothing, a stopped run's claim on a complete frame is cleared, and the frames a
changed setting or an edited texture makes stale are named by the dry run and the run."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import yaml

from farm_util import SCENE, TINY, motion, report


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
