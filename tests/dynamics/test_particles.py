"""Particle systems: seeded emission, vectorised simulation, sampling; and `motion plot`
through the installed CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from _dynamics_scenes import ball, floor, write_scene
from motion.pipeline.dynamics import simulate
from motion.pipeline.scene import load_scene

MOTION = Path(sys.executable).with_name("motion")


def fountain(seed: int = 7, rate: float = 2000.0) -> dict:
    return {
        "name": "spray",
        "shape": "particles",
        "radius": 0.01,
        "transform": {"translate": [0, 0.5, 0]},
        "emitter": {"rate": rate, "lifetime": 0.8, "speed": 4.0, "speed_spread": 1.0, "spread": 20, "seed": seed, "restitution": 0.5, "size": [0.1, 0, 0.1]},
    }


def test_emitter_is_seeded_and_particles_stay_above_the_floor(tmp_path):
    path = write_scene(tmp_path, [fountain(), floor(restitution=0.5)], {"integrator": "semi-implicit-euler", "step": 0.002})
    a = simulate(load_scene(path), 1.5)
    b = simulate(load_scene(path), 1.5)
    times = np.linspace(0.0, 1.5, 37)
    sa, sb = a.particles("spray", times), b.particles("spray", times)
    np.testing.assert_array_equal(sa.positions, sb.positions)
    n = sa.ids.size
    assert n == 2000 * 1.5 + 1
    assert sa.positions.shape == (37, n, 3) and sa.alive.shape == (37, n)
    # alive: born at i / rate, lives 0.8 s
    birth = np.arange(n) / 2000.0
    np.testing.assert_array_equal(sa.alive, (times[:, None] >= birth - 1e-12) & (times[:, None] < birth + 0.8))
    assert np.all(sa.positions[..., 1] >= 0.01 - 1e-6)  # none fell through the floor
    assert np.isfinite(sa.positions).all()
    other = simulate(load_scene(write_scene(tmp_path, [fountain(seed=8), floor(restitution=0.5)], {"step": 0.002}, name="other")), 0.2)
    assert not np.allclose(other.particles("spray", times[:3]).positions[-1, :10], sa.positions[2, :10])


def test_particles_follow_the_ballistic_path_at_sub_frame_times(tmp_path):
    path = write_scene(tmp_path, [fountain(rate=100.0)], {"integrator": "rk4", "step": 1 / 240})
    sim = simulate(load_scene(path), 0.5)
    spawns = sim.systems["spray"].spawns
    t = np.array([0.3127, 0.4011])
    got = sim.particles("spray", t)
    tau = np.clip(t[:, None] - spawns.birth[None, :], 0.0, 0.8)
    expect = spawns.position[None] + spawns.velocity[None] * tau[..., None] + 0.5 * np.array([0, -9.81, 0]) * tau[..., None] ** 2
    np.testing.assert_allclose(got.positions, expect, atol=2e-5)  # float32 records


def run_motion(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(MOTION), *args], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("what", ["energy", "trajectory"])
def test_motion_plot_cli(tmp_path, what):
    path = write_scene(tmp_path, [ball("b", 1.0, restitution=0.7), floor(), fountain(rate=200.0)], {"integrator": "semi-implicit-euler", "step": 0.004}, last=24)
    out = tmp_path / f"{what}.png"
    proc = run_motion("plot", str(path), "--what", what, "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000


def test_motion_plot_reports_a_blow_up_in_one_line(tmp_path):
    objects = [ball("anchor", 0.0, pinned=True, radius=0.01), ball("bob", 0.0, x=1.2, body="particle", radius=0.01)]
    dyn = {"integrator": "euler", "step": 0.01, "gravity": [0, 0, 0], "springs": [{"a": "anchor", "b": "bob", "stiffness": 1.0e6, "rest_length": 1.0}]}
    proc = run_motion("plot", str(write_scene(tmp_path, objects, dyn)), "-o", str(tmp_path / "x.png"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "blew up" in lines[0] and "'bob'" in lines[0] and "Traceback" not in proc.stderr
