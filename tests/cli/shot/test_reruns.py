"""Reruns re-render only what changed (issue 38): a frame is stale when what it shows can
have changed (its own baked motion, the look: scene content, render settings and the files
it reads), never for a name, a comment or a key outside its shutter (docs/reruns.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from farm_util import TINY, motion, report

SHOT = {
    "name": "keys",
    "timeline": {"fps": 24, "first": 0, "last": 7},
    "camera": {"position": [0, 1.5, 4], "look_at": [0, 0.3, 0], "fov": 40, "shutter": {"angle": 180}},
    "lights": [{"type": "constant", "radiance": 0.5}, {"type": "point", "name": "key", "position": [1, 3, 2], "intensity": 30}],
    "materials": [{"name": "red", "type": "diffuse", "color": [0.7, 0.2, 0.1]}, {"name": "grey", "type": "diffuse", "color": 0.5}],
    "objects": [
        {"name": "floor", "shape": "rectangle", "width": 6, "height": 6, "material": "grey", "transform": {"rotate": {"euler": [-90, 0, 0]}}},
        {"name": "box", "shape": "cube", "size": [0.5, 0.5, 0.5], "material": "red", "transform": {"translate": [0, 0.25, 0]},
         "motion": {"type": "keyframes", "channels": {"translate": {"keys": [
             {"time": 0, "value": [-1, 0.25, 0]}, {"time": 4, "value": [0, 0.25, 0]}, {"time": 7, "value": [1, 0.25, 0]}]}}}},
    ],
    "render": {"resolution": [16, 12], "spp": 1, "max_depth": 2, "shutter_samples": 2},
}


def _write(path: Path, doc: dict) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _replace(scene: Path, out: Path) -> list[dict]:
    dry = motion("render", scene, "-o", out, *TINY, "--resume", "--dry-run", "--json")
    assert dry.returncode == 0, dry.stderr
    return json.loads(dry.stdout)["replace"]


def _pixels(path: Path) -> np.ndarray:
    from motion.pipeline.frame_output import read_frame

    return read_frame(path).rgba


def test_moving_one_key_re_renders_exactly_the_frames_whose_shutter_it_touches(tmp_path: Path) -> None:
    """Keys at 0, 4, 7 (linear): moving the last one changes the motion in (4, 7], which
    the shutters of frames 4-7 touch (frame 4's opens at 3.75, closes at 4.25). Those four
    are re-rendered and named with whose motion changed; frames 0-3 are kept, and are bit
    for bit what the edited scene renders from scratch. Before, all 8 were re-rendered
    ("made from another version of the scene or its settings")."""
    out = tmp_path / "out"
    scene = _write(tmp_path / "keys.yaml", SHOT)
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    doc = json.loads(json.dumps(SHOT))
    doc["objects"][1]["motion"]["channels"]["translate"]["keys"][2]["value"] = [1.5, 0.6, 0]
    _write(scene, doc)
    assert _replace(scene, out) == [{"frames": "4-7", "reason": "were made from other motion (motion of box changed)"}]
    run = motion("render", scene, "-o", out, *TINY, "--resume")
    assert run.returncode == 0, run.stderr
    assert "frames 4-7 exist but were made from other motion (motion of box changed): they will be replaced" in run.stderr, run.stderr
    totals = report(out)["totals"]
    assert (totals["rendered"], totals["skipped"]) == (4, 4)
    fresh = tmp_path / "fresh"
    assert motion("render", scene, "-o", fresh, *TINY).returncode == 0
    for f in range(8):
        name = f"keys.{f:04d}.exr"
        assert np.array_equal(_pixels(out / name), _pixels(fresh / name)), f


def test_a_rename_or_a_comment_re_renders_nothing_and_a_material_everything(tmp_path: Path) -> None:
    """Renaming an object, a material and a light (and their references), the scene's
    output comment and a key moved outside every frame's shutter (the timeline ends at 7;
    keys at 30 and 40, the one at 40 moved): nothing is stale. A material's colour: every frame, named.
    Before, the rename re-rendered all 8 to bit-identical pixels."""
    out = tmp_path / "out"
    doc = json.loads(json.dumps(SHOT))
    doc["objects"][1]["motion"]["channels"]["translate"]["keys"] += [{"time": 30, "value": [1, 0.25, 0]}, {"time": 40, "value": [2, 0.25, 0]}]
    scene = _write(tmp_path / "keys.yaml", doc)
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    renamed = json.loads(json.dumps(doc))
    renamed["objects"][1]["name"] = "crate"
    renamed["materials"][0]["name"] = "rust"
    renamed["objects"][1]["material"] = "rust"
    renamed["lights"][1]["name"] = "fill"
    renamed["output"] = {"comments": "take 2"}
    renamed["objects"][1]["motion"]["channels"]["translate"]["keys"][4]["value"] = [3, 2, 1]
    _write(scene, renamed)
    assert _replace(scene, out) == []
    run = motion("render", scene, "-o", out, *TINY, "--resume")
    assert run.returncode == 0 and report(out)["totals"]["rendered"] == 0, run.stderr
    renamed["materials"][1]["color"] = 0.3
    _write(scene, renamed)
    assert _replace(scene, out) == [{"frames": "0-7", "reason": "were made from another version of the scene (material grey changed)"}]


def test_a_second_scene_file_with_the_same_name_is_refused_its_folder(tmp_path: Path) -> None:
    """Two scene files named `keys` share out/keys: the second is refused with one line
    naming both (exit 2, nothing written; before, it replaced the first one's frames as
    "made with other settings"); --overwrite takes the folder over; a scene file renamed
    keeps its folder (the old name is gone: nothing competes for it)."""
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
    a = _write(tmp_path / "a" / "shot.yaml", SHOT)
    doc = json.loads(json.dumps(SHOT))
    doc["render"]["spp"] = 2
    b = _write(tmp_path / "b" / "shot.yaml", doc)
    out = tmp_path / "out" / "keys"
    assert motion("render", a, "--frames", "0-1", *TINY, cwd=tmp_path).returncode == 0
    made = {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")}
    for extra in ([], ["--resume"], ["--dry-run"]):
        refused = motion("render", b, "--frames", "0-1", *TINY, *extra, cwd=tmp_path)
        assert refused.returncode == 2, refused.stderr
        lines = refused.stderr.strip().splitlines()
        assert len(lines) == 1 and str(a) in lines[0] and str(b) in lines[0], refused.stderr
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")} == made
    taken = motion("render", b, "--frames", "0-1", *TINY, "--overwrite", cwd=tmp_path)
    assert taken.returncode == 0 and f"held the frames of {a}" in taken.stderr, taken.stderr
    assert motion("render", a, "--frames", "0-1", *TINY, "--resume", cwd=tmp_path).returncode == 2
    moved = b.rename(tmp_path / "b" / "shot-v2.yaml")
    again = motion("render", moved, "--frames", "0-1", *TINY, "--resume", cwd=tmp_path)
    assert again.returncode == 0 and report(out)["totals"]["skipped"] == 2, again.stderr
    assert json.loads((out / ".motion-shot.json").read_text())["scene"] == "../../b/shot-v2.yaml"


def test_keys_before_a_shot_at_1001_are_named_and_old_frames_are_foreign(tmp_path: Path) -> None:
    """`first: 1001` with keys written as frames 0, 4, 7: validation warns naming them
    (it said ok and the box stood still); the frames 0-7 of the earlier timeline stay in
    the folder as foreign, named, out of the folder's record and of the deliverables
    (before: `folder.complete` "0-7,1001-1008" and a contact sheet of 16)."""
    scene = _write(tmp_path / "keys.yaml", SHOT)
    out = tmp_path / "out"
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    doc = json.loads(json.dumps(SHOT))
    doc["timeline"].update(first=1001, last=1008)
    _write(scene, doc)
    checked = motion("validate", scene)
    assert checked.returncode == 0, checked.stderr
    assert ("warning: objects[1].motion.channels.translate: keys at frames 0, 4, 7 lie outside the timeline (frames 1001-1008): all lie before it: "
            "the shot holds the value of the last one (a key's time counts from frame 0, not from timeline.first)") in checked.stderr, checked.stderr
    run = motion("render", scene, "-o", out, *TINY, "--deliver", "24p,contact")
    assert run.returncode == 0, run.stderr
    assert "frames 0-7 lie outside the timeline 1001-1008: foreign" in run.stderr, run.stderr
    rep = report(out)
    assert rep["folder"]["complete"] == "1001-1008" and rep["foreign"] == "0-7"
    manifest = json.loads((out / "deliver" / "manifest.json").read_text())
    made = {name: entry["versions"][entry["latest"]]["frames"] for name, entry in manifest["deliverables"].items()}
    assert made == {"24p": "1001-1008", "contact": "1001-1008"}
    from motion.pipeline.scene import load_scene
    from motion.pipeline.shot.stale import folder_frames

    found = folder_frames(out, load_scene(scene))
    assert sorted(found.timeline) == list(range(1001, 1009)) and sorted(found.foreign) == list(range(8))


def _dry_estimate(scene: Path, out: Path, cache: Path, kernels: Path) -> dict:
    import os
    import subprocess

    from farm_util import MOTION

    env = {**os.environ, "MOTION_CACHE_DIR": str(cache), "DRJIT_CACHE_DIR": str(kernels)}
    res = subprocess.run([MOTION, "render", str(scene), "-o", str(out), *TINY, "--dry-run", "--json"], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)["estimate"]


def test_a_new_machine_estimates_compiling_every_kernel(tmp_path: Path) -> None:
    """A machine with an empty kernel cache and no history (a fresh clone, a fresh CI
    runner) is estimated to compile every kernel in each worker's first frame (the first
    run took 99.8 s against 10.4 s estimated: the built-in cold frame was 0.8 s); with
    kernels in the cache the cold frame is the short one. Once a run that compiled is
    recorded, the machine's own figure replaces the built-in one."""
    from motion.pipeline.shot.estimate import DEFAULT_COLD_EXTRA_S, DEFAULT_COMPILE_EXTRA_S

    scene = _write(tmp_path / "keys.yaml", SHOT)
    fresh = _dry_estimate(scene, tmp_path / "out", tmp_path / "cache", tmp_path / "kernels")
    assert fresh["compiles_kernels"] and fresh["cold_extra_s"] == DEFAULT_COMPILE_EXTRA_S and "empty kernel cache" in fresh["basis"], fresh
    assert fresh["seconds"] > DEFAULT_COMPILE_EXTRA_S
    kernels = tmp_path / "warm-kernels"
    kernels.mkdir()
    (kernels / ("0123abcd" * 4 + ".llvm.v6.bin")).write_bytes(bytes(100_000))  # what drjit leaves after compiling a render's kernels
    cached = _dry_estimate(scene, tmp_path / "out", tmp_path / "cache", kernels)
    assert not cached["compiles_kernels"] and cached["cold_extra_s"] == DEFAULT_COLD_EXTRA_S, cached

    import os

    # the session's cache root comes back afterwards (deleting it left later tests of this
    # worker in the user's own cache root)
    old = os.environ.get("MOTION_CACHE_DIR")
    os.environ["MOTION_CACHE_DIR"] = str(tmp_path / "cache")
    try:
        from motion.pipeline.shot.estimate import record

        rows = [{"frame": 0, "status": "rendered", "cold": True, "render_s": 40.0, "kernels_compiled": 12},
                *({"frame": f, "status": "rendered", "cold": False, "render_s": 1.0, "kernels_compiled": 0} for f in (1, 2))]
        record("other-shot", "h", 1000, {"frames": rows, "workers": [{}], "totals": {"farm_s": 44.0}}, compiled_all=True)
    finally:
        if old is None:
            del os.environ["MOTION_CACHE_DIR"]
        else:
            os.environ["MOTION_CACHE_DIR"] = old
    learned = _dry_estimate(scene, tmp_path / "out", tmp_path / "cache", tmp_path / "empty")
    assert learned["compiles_kernels"] and learned["cold_extra_s"] == 39.0 and "as in 1 runs here" in learned["basis"], learned


def test_the_first_eta_counts_the_cold_costs_down_before_the_warm_frames() -> None:
    """Before two frames are measured the ETA is the plan's start-up and cold first frames
    still to come plus the warm frames left (it was the warm frames only: 6 s with 90 s
    left); once frames are measured, the measured rate."""
    import time

    from motion.pipeline.farm.progress import Progress

    p = Progress(total=10, live=False, estimate_s=1.0, overhead_s=30.0)
    assert 39.0 < p.eta_s <= 40.0  # type: ignore[operator]
    p.t0 = time.monotonic() - 100.0  # the cold costs are behind it
    assert p.eta_s == 10.0
