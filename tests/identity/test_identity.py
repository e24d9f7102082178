"""A frame's identity (pipeline/identity/, docs/identity.md): kept in the cache layer so a
rerun that renders nothing bakes nothing, whole frames known by their unchanged files, the
denoiser probe's answer kept; a damaged entry is not believed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from _dynamics_scenes import dust_shot
from _support import run_motion
from farm_util import report

KEPT_SIMULATION = "kept from an earlier run"

SHOT = dust_shot("ident", 1004, 0.01, 0.1)


def _render(scene: Path, out: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    done = run_motion("render", str(scene), "-o", str(out), "--resume", "--no-progress", env=env)
    assert done.returncode == 0, done.stderr
    return done


@pytest.mark.render
def test_a_rerun_that_renders_nothing_bakes_nothing_and_a_missing_frame_is_rendered_the_same(tmp_path: Path) -> None:
    """The first run simulates, bakes and keeps its frames' identities; a rerun over the
    same frames finds every frame complete from the kept identities: no simulation read, no
    bake (the report has no `simulation`, its bake took no time). A frame removed is
    rendered again (that run bakes) bit for bit as it was."""
    from motion.pipeline.frame_output import read_frame

    env = {"MOTION_CACHE_DIR": str(tmp_path / "cache")}
    scene = tmp_path / "ident.yaml"
    scene.write_text(yaml.safe_dump(SHOT, sort_keys=False))
    out = tmp_path / "out"
    _render(scene, out, env)
    assert report(out)["simulation"] == "simulated"
    assert len(list((tmp_path / "cache" / "frame-keys").glob("keys-*.json"))) == 1
    before = read_frame(out / "ident.1003.exr").rgba

    again = _render(scene, out, env)
    rerun = report(out)
    assert rerun["totals"]["skipped"] == 4 and rerun["totals"]["rendered"] == 0
    assert "simulation" not in rerun and rerun["totals"]["bake_s"] < 0.01 and KEPT_SIMULATION not in again.stderr

    (out / "ident.1003.exr").unlink()
    _render(scene, out, env)
    third = report(out)
    assert third["totals"]["rendered"] == 1 and third["simulation"] == "kept"
    assert np.array_equal(read_frame(out / "ident.1003.exr").rgba, before)


@pytest.mark.render
def test_a_damaged_kept_entry_is_not_believed_and_the_run_bakes(tmp_path: Path) -> None:
    """Kept identities that are not of the format (a motion digest that is no digest) are
    one warning; the run bakes, keeps its frames and replaces the entry."""
    env = {"MOTION_CACHE_DIR": str(tmp_path / "cache")}
    scene = tmp_path / "ident.yaml"
    scene.write_text(yaml.safe_dump(SHOT, sort_keys=False))
    out = tmp_path / "out"
    _render(scene, out, env)
    entry = next((tmp_path / "cache" / "frame-keys").glob("keys-*.json"))
    doc = json.loads(entry.read_text())
    doc["frames"]["1002"]["motion_hash"] = "not a digest"
    entry.write_text(json.dumps(doc))
    again = _render(scene, out, env)
    assert "kept frame identities" in again.stderr and "damaged" in again.stderr
    assert report(out)["simulation"] == "kept" and report(out)["totals"]["skipped"] == 4
    assert json.loads(entry.read_text())["frames"]["1002"]["motion_hash"] != "not a digest"


def test_a_frame_changed_on_disk_is_decoded_again(tmp_path: Path) -> None:
    """A frame found whole is known whole while its file is unchanged; cut short with its
    modification time set back, it is decoded again (its status-change time moved) and
    found damaged."""
    from motion.pipeline.frame_output import write_frame
    from motion.pipeline.identity.record import WholeFrames

    path = write_frame(tmp_path / "f.0001.exr", np.full((8, 8, 4), 0.5, np.float32), {"frame": 1}, compression="none")
    first = WholeFrames()
    assert first.is_whole(path) and path.name in first.found
    assert WholeFrames(first.found).is_whole(path)
    st = path.stat()
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 64])
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    later = WholeFrames(first.found)
    assert not later.is_whole(path) and path.name not in later.found


def test_the_denoiser_probes_answer_is_kept_for_the_next_process(tmp_path: Path) -> None:
    """The first process probes OIDN and keeps its answer in the cache layer; the next
    process reads the kept answer instead of probing (shown by an answer only the entry
    holds)."""
    pytest.importorskip("mitsuba_oidn")
    env = {**os.environ, "MOTION_CACHE_DIR": str(tmp_path / "cache")}
    code = "import json; from motion.pipeline.render.output.denoise import probe; print(json.dumps(probe()))"
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert first.returncode == 0 and "error" not in json.loads(first.stdout), first.stdout + first.stderr
    entry = next((tmp_path / "cache" / "probes").glob("oidn-*.json"))
    entry.write_text(json.dumps({**json.loads(entry.read_text()), "version": "kept-answer"}))
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert json.loads(second.stdout)["version"] == "kept-answer"
