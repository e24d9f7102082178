"""Bake: per-frame shutter sampling, JSON/NPZ layout, the real CLI, dynamics hand-off."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.bake import BakeFileError, bake, read_baked, write_baked
from motion.pipeline.motion import Pose, evaluate
from motion.pipeline.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
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
        for a, b in zip(f.motion.objects[name], pose):
            np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(f.at_frame.objects["hips"].translation, [[0.6, 0.95, 0.0]], atol=1e-12)
    with pytest.raises(KeyError):
        baked.frame(5)


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
    npz = read_baked(write_baked(baked, tmp_path / "m.npz"))
    arrays = npz["arrays"]
    assert npz["samples_per_frame"] == 9 and npz["fps"] == "24"
    assert arrays["frames"].tolist() == [0, 1, 2]
    assert arrays["samples/objects/top/rotation"].shape == (3, 9, 4)
    assert arrays["at_frame/objects/top/rotation"].shape == (3, 4)
    assert arrays["samples/camera_scalars/fov"].shape == (3, 9)
    np.testing.assert_array_equal(arrays["samples/objects/fin_a/rotation"][1], baked.frames[1].motion.objects["fin_a"].rotation)
    doc = read_baked(write_baked(baked, tmp_path / "m.json"))
    frame = doc["frames"][2]
    assert frame["frame"] == 2 and len(frame["sample_times"]) == 9
    np.testing.assert_allclose(frame["samples"]["objects"]["top"]["rotation"], arrays["samples/objects/top/rotation"][2])
    np.testing.assert_allclose(frame["at_frame"]["camera"]["translation"], arrays["at_frame/camera/translation"][2])
    with pytest.raises(BakeFileError, match="unknown extension"):
        write_baked(baked, tmp_path / "m.txt")
    (tmp_path / "bad.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(BakeFileError, match="not a baked-motion file"):
        read_baked(tmp_path / "bad.json")


def test_bake_simulates_dynamics_when_no_simulation_given(monkeypatch: pytest.MonkeyPatch) -> None:
    import motion.pipeline.dynamics as dynamics

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
    np.testing.assert_allclose(baked.frame(95).motion.objects["ball_lo"].translation[:, 0], baked.frame(95).sample_times)


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
