"""Bake: per-frame shutter sampling, JSON/NPZ layout, the real CLI, dynamics hand-off."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from motion.pipeline.bake import BakeFileError, FrameNotBakedError, bake, read_baked, write_baked
from motion.pipeline.motion import Pose, evaluate
from motion.pipeline.scene import load_scene

if TYPE_CHECKING:
    from motion.pipeline.bake import BakedFrame

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
MOTION = ROOT / ".venv" / "bin" / "motion"


def test_frames_shutters_and_samples() -> None:
    loaded = load_scene(SCENES / "walk-cycle.yaml")
    baked = bake(loaded, [0, 12])
    f = baked.frame(12)
    # 24 fps, 180-degree centred shutter: open for 1/48 s around t = 0.5
    assert f.time == 0.5
    assert f.shutter == pytest.approx((0.5 - 1 / 96, 0.5 + 1 / 96), abs=1e-15)
    assert len(f.sample_times) == loaded.scene.render.shutter_samples == 9
    assert f.sample_times[0] == f.shutter[0] and f.sample_times[-1] == f.shutter[1]
    direct = evaluate(loaded, f.sample_times)
    for name, pose in direct.objects.items():
        np.testing.assert_allclose(f.across_shutter.objects[name].matrices(), pose.matrices(), atol=1e-12)
    np.testing.assert_allclose(f.at_frame.objects["hips"].translation, [[0.6, 0.95, 0.0]], atol=1e-12)
    with pytest.raises(FrameNotBakedError, match="frame 5 is not in this bake"):
        baked.frame(5)


def test_a_long_bake_holds_arrays_not_a_record_per_frame(tmp_path: Path) -> None:
    """A bake keeps its one vectorised evaluation and makes each frame's record when asked,
    so the farm's client holds arrays, not thousands of small records: 5,000 frames of the
    farm test scene cost under 2.5 KB a frame (about 9.6 KB as a list of records: a
    100,000-frame job held 1.16 GB). The records it makes are the ones a bake of that
    frame alone gives (fingerprint), in order and by number."""
    import tracemalloc

    from motion.pipeline.bake import by_number
    from motion.pipeline.identity import fingerprint

    scene = tmp_path / "long.yaml"
    scene.write_text((ROOT / "tests" / "data" / "farm-tiny.yaml").read_text().replace("last: 47", "last: 4999"))
    loaded = load_scene(scene)
    bake(loaded, [0])  # imports and first-call caches outside the measurement
    tracemalloc.start()
    try:
        baked = bake(loaded, range(5000))
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert held / 5000 < 2500, f"{held / 5000:.0f} bytes a frame"
    assert len(baked.frames) == 5000 and [f.frame for f in baked.frames[:3]] == [0, 1, 2]
    frames = by_number(baked.frames)
    for f in (0, 1234, 4999):
        alone = bake(loaded, [f]).frames[0]
        assert fingerprint([baked.frame(f)]) == fingerprint([frames[f]]) == fingerprint([alone])
    assert baked.frames[-1].frame == 4999 and 5000 not in frames


def test_bake_cli_frames_and_preset(tmp_path: Path) -> None:
    """`motion bake` reads frames with the render grammar and can apply a preset."""
    import json
    import subprocess
    import sys

    motion = str(Path(sys.executable).with_name("motion"))
    out = tmp_path / "wc.json"
    proc = subprocess.run([motion, "bake", str(SCENES / "walk-cycle.yaml"), "-o", str(out), "--frames", "0-10x5", "--preset", "ci-smoke"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert [f["frame"] for f in doc["frames"]] == [0, 5, 10]
    assert doc["samples_per_frame"] == 5  # ci-smoke's shutter_samples, not the scene's 9
    for bad in ("a-b", "5-2", "40-60"):
        proc = subprocess.run([motion, "bake", str(SCENES / "walk-cycle.yaml"), "-o", str(out), "--frames", bad], capture_output=True, text=True)
        assert proc.returncode == 2 and "--frames" in proc.stderr and "Traceback" not in proc.stderr


def test_npz_and_json_layouts(tmp_path: Path) -> None:
    loaded = load_scene(SCENES / "spinning-top.yaml")
    baked = bake(loaded, [0, 1, 2])
    with np.load(write_baked(baked, tmp_path / "m.npz")) as data:
        arrays = {k: data[k] for k in data.files}
    npz = json.loads(str(arrays["meta"]))
    assert npz["samples_per_frame"] == 9 and npz["fps"] == "24"
    assert arrays["frames"].tolist() == [0, 1, 2]
    assert arrays["samples/objects/top/rotation"].shape == (3, 9, 4)
    assert arrays["at_frame/objects/top/rotation"].shape == (3, 4)
    assert arrays["samples/camera_scalars/fov"].shape == (3, 9)
    np.testing.assert_array_equal(arrays["samples/objects/fin_a/rotation"][1], baked.frames[1].across_shutter.objects["fin_a"].rotation)
    doc = json.loads(write_baked(baked, tmp_path / "m.json").read_text())
    frame = doc["frames"][2]
    assert frame["frame"] == 2 and len(frame["sample_times"]) == 9
    np.testing.assert_allclose(frame["samples"]["objects"]["top"]["rotation"], arrays["samples/objects/top/rotation"][2])
    np.testing.assert_allclose(frame["at_frame"]["camera"]["translation"], arrays["at_frame/camera/translation"][2])
    with pytest.raises(BakeFileError, match="unknown extension"):
        write_baked(baked, tmp_path / "m.txt")
    (tmp_path / "bad.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(BakeFileError, match="not a baked-motion file"):
        read_baked(tmp_path / "bad.json")


def test_bake_simulates_dynamics_when_no_simulation_given(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import motion.pipeline.dynamics as dynamics

    # a cache root of its own: a simulation another test kept (bake/keep.py) is not simulated again
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))

    calls: list[tuple[float, float]] = []

    class Sim:
        def sample(self, times: np.ndarray) -> dict[str, Pose]:
            n = len(times)
            pose = Pose(np.zeros((n, 3)) + times[:, None], np.tile([1.0, 0, 0, 0], (n, 1)), np.ones((n, 3)))
            return {"ball_hi": pose, "ball_mid": pose, "ball_lo": pose}

    def fake_simulate(loaded, t_end: float, t_start: float = 0.0):  # type: ignore[no-untyped-def]
        calls.append((t_start, t_end))
        return Sim()

    monkeypatch.setattr(dynamics, "simulate", fake_simulate, raising=False)
    baked = bake(load_scene(SCENES / "bouncing-balls.yaml"), [0, 95])
    assert len(calls) == 1
    t_start, t_end = calls[0]
    assert t_start == pytest.approx(-1 / 96) and t_end == pytest.approx(95 / 24 + 1 / 96)
    np.testing.assert_allclose(baked.frame(95).across_shutter.objects["ball_lo"].translation[:, 0], baked.frame(95).sample_times)


def test_cli_bake_walk_cycle(tmp_path: Path) -> None:
    out = tmp_path / "x.json"
    proc = subprocess.run([str(MOTION), "bake", str(SCENES / "walk-cycle.yaml"), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "48 frames x 9 shutter samples" in proc.stdout
    doc = json.loads(out.read_text())
    assert len(doc["frames"]) == 48
    assert doc["frames"][24]["at_frame"]["objects"]["hips"]["translation"] == pytest.approx([1.2, 0.95, 0.0])
    bad = subprocess.run([str(MOTION), "bake", str(SCENES / "walk-cycle.yaml"), "-o", str(out), "--frames", "x"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "--frames" in bad.stderr and "Traceback" not in bad.stderr


# --- the contract: one reader, one fingerprint ---------------------------------------------


def _every_kind_frame(seed: int = 0) -> "BakedFrame":
    """A BakedFrame (N = 3) with every kind of animated value: an object, the camera with
    fov and ortho_width, a light with a colour and a scalar channel, a deforming mesh's
    vertices and a particle system."""
    from motion.pipeline.bake import BakedFrame
    from motion.pipeline.dynamics.particles import ParticleSamples
    from motion.pipeline.motion import SceneMotion

    rng = np.random.default_rng(seed)

    def motion(times: np.ndarray) -> SceneMotion:
        t = len(times)

        def pose() -> Pose:
            q = rng.normal(size=(t, 4))
            return Pose(rng.normal(size=(t, 3)), q / np.linalg.norm(q, axis=1, keepdims=True), rng.uniform(0.5, 2, (t, 3)))

        return SceneMotion(
            times=times,
            objects={"box": pose()},
            camera=pose(),
            camera_scalars={"fov": rng.uniform(20, 60, t), "ortho_width": rng.uniform(1, 3, t)},
            lights={"key": pose()},
            light_scalars={"key": {"intensity": rng.uniform(0, 9, (t, 3)), "scale": rng.uniform(0, 1, t)}},
            vertices={"cloth": rng.normal(size=(t, 4, 3))},
            particles={"spray": ParticleSamples(ids=np.arange(5), positions=rng.normal(size=(t, 5, 3)), alive=rng.uniform(size=(t, 5)) > 0.5)},
        )

    samples = np.array([0.49, 0.5, 0.51])
    return BakedFrame(frame=12, time=0.5, shutter=(0.49, 0.51), sample_times=samples, at_frame=motion(np.array([0.5])), across_shutter=motion(samples))


def test_fingerprint_changes_with_any_animated_value() -> None:
    """Property: changing any single number anywhere in a baked frame (every leaf the
    generic walk finds: objects, camera, fov, ortho_width, lights, light scalars,
    vertices, particles, times) changes the fingerprint."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from motion.pipeline.identity import fingerprint, leaves

    frame = _every_kind_frame()
    base = fingerprint([frame])
    keys = [k for k, _ in leaves(frame)]
    for kind in ("objects/box", "/camera/", "camera_scalars/fov", "camera_scalars/ortho_width", "lights/key", "light_scalars/key/intensity",
                 "light_scalars/key/scale", "vertices/cloth", "particles/spray/positions", "particles/spray/alive"):
        assert any(kind in k for k in keys), kind
    assert fingerprint([_every_kind_frame()]) == base  # stable

    def arrays(value: object) -> list[np.ndarray]:
        """The record's own mutable arrays, in the walk's order."""
        import dataclasses

        if dataclasses.is_dataclass(value):
            return [a for f in dataclasses.fields(value) for a in arrays(getattr(value, f.name))]
        if isinstance(value, dict):
            return [a for k in sorted(value) for a in arrays(value[k])]
        if isinstance(value, tuple):
            return [a for v in value for a in arrays(v)]
        return [value] if isinstance(value, np.ndarray) else []

    @settings(max_examples=200, deadline=None, derandomize=True)
    @given(st.data())
    def check(data: st.DataObject) -> None:
        f = _every_kind_frame()
        leaf = data.draw(st.sampled_from(arrays(f)))
        i = data.draw(st.integers(0, leaf.size - 1))
        flat = leaf.reshape(-1)
        old = flat[i]
        if leaf.dtype == bool:
            flat[i] = not old
        else:
            flat[i] = old + data.draw(st.sampled_from([1, -3] if leaf.dtype.kind in "iu" else [1e-9, -0.5, 3.0]))
        assert fingerprint([f]) != base

    check()
    # the scalar fields outside the arrays too
    import dataclasses

    for change in ({"frame": 13}, {"time": 0.51}, {"shutter": (0.49, 0.52)}):
        assert fingerprint([dataclasses.replace(frame, **change)]) != base


def test_read_baked_returns_the_records_that_were_written(tmp_path: Path) -> None:
    """JSON and NPZ read back into BakedMotion; a rigid scene's frames fingerprint as the
    bake's (what `--resume --motion` relies on); NPZ brings vertices across the shutter."""
    from motion.pipeline.identity import fingerprint

    baked = bake(load_scene(SCENES / "spinning-top.yaml"), [0, 5])
    for ext in ("json", "npz"):
        back = read_baked(write_baked(baked, tmp_path / f"m.{ext}"))
        assert (back.scene, back.fps, back.shutter_angle, back.shutter_position) == (baked.scene, baked.fps, baked.shutter_angle, baked.shutter_position)
        assert [f.frame for f in back.frames] == [0, 5] and back.samples_per_frame == 9
        assert fingerprint(back.frames) == fingerprint(baked.frames), ext
    # NPZ: a deforming mesh's vertices and a particle system, at the frame and across the
    # shutter, come back bit for bit (every leaf: the fingerprint)
    for name, objs in (("flock", ["darts"]), ("cannonball-splash", ["splash", "crown"])):
        loaded = load_scene(SCENES / f"{name}.yaml", {"render": {"shutter_samples": 3}})
        fb = bake(loaded, [2, 40])
        back = read_baked(write_baked(fb, tmp_path / f"{name}.npz"))
        assert fingerprint(back.frames) == fingerprint(fb.frames), name
        heavy = "vertices" if name == "flock" else "particles"
        for f in back.frames:
            assert sorted(getattr(f.at_frame, heavy)) == sorted(objs) == sorted(getattr(f.across_shutter, heavy))


def test_read_baked_refuses_a_broken_frame(tmp_path: Path) -> None:
    baked = bake(load_scene(SCENES / "spinning-top.yaml"), [0, 1])
    doc = json.loads(write_baked(baked, tmp_path / "m.json").read_text())
    doc["frames"][1]["samples"]["lights"] = {"light0": {"translation": [[0, 0, 0]] * 9, "rotation": [[0, 0, 0, 0]] * 9, "scale": [[1, 1, 1]] * 9}}
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(BakeFileError, match=r"m.json: frame 1: light 'light0': rotation is not a unit quaternion"):
        read_baked(tmp_path / "m.json")
    doc["frames"][1]["samples"] = {}
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(BakeFileError, match="frame 1 is malformed"):
        read_baked(tmp_path / "m.json")


def test_farm_motion_file_takes_nonrigid_scenes_from_npz_only(tmp_path: Path) -> None:
    from motion.pipeline.identity import fingerprint
    from motion.pipeline.errors import UsageError
    from motion.pipeline.farm.frame_inputs import file_inputs

    flock = load_scene(SCENES / "flock.yaml", {"render": {"shutter_samples": 3}})
    baked = bake(flock, [2, 3])
    frames = file_inputs(flock, write_baked(baked, tmp_path / "f.npz"), [3])
    assert fingerprint(frames) == fingerprint([baked.frame(3)])  # what the farm renders: the bake's own
    with pytest.raises(UsageError, match=r"whose geometry a JSON bake does not carry; bake to \.npz"):
        file_inputs(flock, write_baked(baked, tmp_path / "f.json"), [3])
    # an NPZ without the frame-time geometry (as written before it was carried) is refused
    arrays = dict(np.load(tmp_path / "f.npz"))
    np.savez_compressed(tmp_path / "old.npz", **{k: v for k, v in arrays.items() if not k.startswith("at_frame/vertices/")})
    with pytest.raises(UsageError, match="no frame-time geometry for darts"):
        file_inputs(flock, tmp_path / "old.npz", [3])
    # frame-time vertices that do not match the shutter samples' are a located error
    arrays["at_frame/vertices/darts"] = arrays["at_frame/vertices/darts"][:, :-1]
    np.savez_compressed(tmp_path / "bad.npz", **arrays)
    with pytest.raises(BakeFileError, match=r"bad.npz: frame 2: the vertices of 'darts' at the frame time have shape"):
        read_baked(tmp_path / "bad.npz")
