"""`motion plot` draws time on the dynamics clock, the one every `start`/`stop` of a
dynamics block reads: seconds from the first frame (0 there, whatever its number), not the
scene's clock (41.7 s at frame 1001 of a 24 fps shot)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _dynamics_scenes import ball, floor, write_scene
from _support import run_motion
from farm_util import motion


def _shot(tmp_path: Path) -> Path:
    path = write_scene(tmp_path, [floor(), ball("ball", 1.0, start=0.25)], name="clock", last=11)
    path.write_text(path.read_text().replace("first: 0", "first: 1001").replace("last: 11", "last: 1012"))
    return path


@pytest.mark.parametrize("what", ["energy", "trajectory"])
def test_the_time_axis_counts_from_the_first_frame(tmp_path: Path, what: str) -> None:
    """First frame 1001 at 24 fps, 180-degree centred shutter: the simulation runs from the
    first frame's shutter open (-1/96 s on the dynamics clock) to the last one's close
    (11/24 + 1/96 s); the axis says which clock."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from motion.pipeline.bake import simulate_for
    from motion.pipeline.dynamics.plots import CLOCK, energy_figure, trajectory_figure
    from motion.pipeline.scene import load_scene

    loaded = load_scene(_shot(tmp_path))
    fig = (energy_figure if what == "energy" else trajectory_figure)(plt, loaded, simulate_for(loaded))
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == CLOCK and "first frame" in CLOCK
        x = ax.lines[0].get_xdata()
        assert x[0] == pytest.approx(-1 / 96, abs=1e-9) and x[-1] == pytest.approx(11 / 24 + 1 / 96, abs=1e-9)
    finally:
        plt.close(fig)


def test_until_is_on_the_same_clock(tmp_path: Path) -> None:
    """`--until 0.3` on a shot numbered from 1001 is 0.3 s after its first frame (before, it
    was refused: "expected a time after the simulation's start (41.7 s)")."""
    proc = run_motion("plot", str(_shot(tmp_path)), "--until", "0.3", "-o", str(tmp_path / "e.png"), env={"MOTION_CACHE_DIR": str(tmp_path / "cache")})
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "e.png").stat().st_size > 0


def test_energy_per_body_with_its_zero_at_height_0(tmp_path: Path) -> None:
    from _dynamics_scenes import ball, floor, write_scene

    from motion.pipeline.dynamics import simulate
    from motion.pipeline.scene import load_scene

    path = write_scene(tmp_path, [ball("a", 2.0, mass=0.5), ball("b", 1.0, x=1.0, mass=2.0), floor(restitution=0.5)], {"integrator": "rk4", "step": 0.002})
    sim = simulate(load_scene(path), 0.3)  # before either lands
    energies = {name: (k, p) for name, _, k, p in sim.body_energy()}
    assert set(energies) == {"a", "b"}
    for name, m, h in (("a", 0.5, 2.0), ("b", 2.0, 1.0)):
        k, p = energies[name]
        assert p[0] == pytest.approx(m * 9.81 * h) and np.allclose(k + p, m * 9.81 * h, rtol=1e-9)
    res = motion("plot", path, "--what", "energy", "-o", tmp_path / "e.png")
    assert res.returncode == 0 and (tmp_path / "e.png").stat().st_size > 10_000, res.stderr
