"""The kept simulation (bake/keep.py): a run whose dynamics inputs did not change reads the
simulation an earlier run kept instead of simulating again; a changed dynamics input
simulates again; a damaged or forged entry is discarded with one warning; frames are bit
for bit the same either way."""

from __future__ import annotations

import io
import json
import logging
from pathlib import Path

import numpy as np
import pytest
import yaml

from _dynamics_scenes import dust_shot
from _support import run_motion
from farm_util import report

KEPT = "kept from an earlier run"

SHOT = dust_shot("keep", 1012, 0.1, 0.2)


def _write(path: Path, doc: dict, comment: str = "") -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False) + comment)
    return path


@pytest.fixture
def root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A cache root of the test's own."""
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _simulate(path: Path, caplog: pytest.LogCaptureFixture):
    """simulate_for of the scene at `path`, and whether it said the simulation was kept."""
    from motion.pipeline.bake import simulate_for
    from motion.pipeline.scene.loader import load_scene

    caplog.clear()
    with caplog.at_level(logging.INFO, logger="motion"):
        sim = simulate_for(load_scene(path))
    return sim, any(KEPT in r.getMessage() for r in caplog.records)


def _same(a, b) -> None:
    times = np.linspace(a.t_start, a.t_end, 17)
    for name, pose in a.sample(times).items():
        np.testing.assert_array_equal(pose.translation, b.sample(times)[name].translation)
        np.testing.assert_array_equal(pose.rotation, b.sample(times)[name].rotation)
    for name in a.particle_systems:
        np.testing.assert_array_equal(a.particles(name, times).positions, b.particles(name, times).positions)
        np.testing.assert_array_equal(a.particles(name, times).alive, b.particles(name, times).alive)
    assert (a.t_start, a.t_end, a.step, a.body_names) == (b.t_start, b.t_end, b.step, b.body_names)


def test_second_run_reads_the_kept_simulation_and_it_is_the_same(tmp_path: Path, root: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The first run simulates and keeps; the second (a comment, the scene's name, a
    material's colour, the render settings changed: none moves anything) reads it back,
    array for array what the first simulated."""
    scene = _write(tmp_path / "s.yaml", SHOT)
    first, kept = _simulate(scene, caplog)
    assert not kept
    assert len(list((root / "simulations").glob("sim-*.npz"))) == 1
    doc = json.loads(json.dumps(SHOT))
    doc["name"] = "renamed"
    doc["materials"][0]["color"] = [0.1, 0.7, 0.1]
    doc["render"] = {"resolution": [8, 8], "spp": 1, "shutter_samples": 5}
    _write(scene, doc, "# a comment\n")
    second, kept = _simulate(scene, caplog)
    assert kept
    _same(first, second)


@pytest.mark.parametrize("edit", ["mass", "gravity", "timeline", "emitter"])
def test_a_changed_dynamics_input_simulates_again(tmp_path: Path, root: Path, caplog: pytest.LogCaptureFixture, edit: str) -> None:
    """A body's mass, gravity, the timeline (the simulated range) or an emitter's rate
    changes the key: simulated again, not read."""
    scene = _write(tmp_path / "s.yaml", SHOT)
    _simulate(scene, caplog)
    doc = json.loads(json.dumps(SHOT))
    if edit == "mass":
        doc["objects"][1]["motion"]["mass"] = 3.0
    elif edit == "gravity":
        doc["dynamics"] = {"gravity": [0, -5, 0]}
    elif edit == "timeline":
        doc["timeline"]["last"] = 1014
    else:
        doc["objects"][2]["emitter"]["rate"] = 500
    _write(scene, doc)
    _, kept = _simulate(scene, caplog)
    assert not kept
    assert len(list((root / "simulations").glob("sim-*.npz"))) == 2


@pytest.mark.parametrize("damage", ["truncated", "flipped", "garbage", "forged-record", "forged-shape"])
def test_a_damaged_or_forged_entry_is_discarded_with_one_warning(tmp_path: Path, root: Path, caplog: pytest.LogCaptureFixture, damage: str) -> None:
    """A truncated entry, a flipped byte, a file that is no .npz, an entry whose outline
    names a class outside the simulation's records, or one whose arrays have the wrong
    shape (a well-formed file, CRCs right): one warning, simulated again (no traceback,
    nothing executed), and the new simulation is kept in its place."""
    scene = _write(tmp_path / "s.yaml", SHOT)
    fresh, _ = _simulate(scene, caplog)
    entry = next((root / "simulations").glob("sim-*.npz"))
    data = entry.read_bytes()
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "flipped":
        data = bytearray(data)
        data[len(data) // 2] ^= 0x40
        data = bytes(data)
    elif damage == "garbage":
        data = b"not an npz at all"
    else:
        with np.load(io.BytesIO(data)) as npz:
            arrays = {k: npz[k] for k in npz.files if not k.startswith("__")}
            outline = npz["__outline__"].tobytes().decode()
        if damage == "forged-record":
            outline = outline.replace('"record":"Track"', '"record":"Popen"', 1)
        else:
            first = sorted(arrays, key=lambda k: -arrays[k].size)[0]
            arrays[first] = arrays[first].ravel()[:3].copy()
        raw = outline.encode()
        buf = io.BytesIO()
        np.savez(buf, **arrays, __outline__=np.frombuffer(raw, np.uint8))
        data = buf.getvalue()
    entry.write_bytes(data)
    again, kept = _simulate(scene, caplog)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert not kept
    assert len(warnings) == 1 and "damaged" in warnings[0] and str(entry) in warnings[0], warnings
    _same(fresh, again)
    third, kept = _simulate(scene, caplog)  # kept again, whole
    assert kept


@pytest.mark.render
def test_ci_smoke_reads_the_kept_simulation_and_renders_the_same_pixels(tmp_path: Path) -> None:
    """Two frames rendered in one folder keep the simulation (first run: simulated); the
    ci-smoke job of the same scene in a fresh folder reads it (its three frames are a
    subset of the timeline the simulation covers) and its frames 1001 and 1012 are bit for
    bit those of the first run. Each run's report says which (`simulation`)."""
    from motion.pipeline.frame_output import read_frame

    env = {"MOTION_CACHE_DIR": str(tmp_path / "cache")}
    scene = _write(tmp_path / "keep.yaml", SHOT)
    first = run_motion("render", str(scene), "--preset", "ci-smoke", "--frames", "1001,1012", "-o", str(tmp_path / "a"), "--no-progress", env=env)
    assert first.returncode == 0, first.stderr
    assert KEPT not in first.stderr and report(tmp_path / "a")["simulation"] == "simulated"
    smoke = run_motion("render", str(scene), "--preset", "ci-smoke", "-o", str(tmp_path / "b"), "--no-progress", env=env)
    assert smoke.returncode == 0, smoke.stderr
    assert KEPT in smoke.stderr and report(tmp_path / "b")["simulation"] == "kept"
    for frame in (1001, 1012):
        a = read_frame(tmp_path / "a" / f"keep.{frame}.exr").rgba
        b = read_frame(tmp_path / "b" / f"keep.{frame}.exr").rgba
        assert a.shape == b.shape and np.array_equal(a, b)
