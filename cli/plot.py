"""`motion plot SCENE --what energy|trajectory -o FILE.png`: the pictures a TD looks at to
judge a simulation (motion.pipeline.dynamics.plots)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from motion.cli.options import GivenPath


@click.command()
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--what", type=click.Choice(["energy", "trajectory"]), default="energy", show_default=True, help="energy over time (per body), or body trajectories")
@click.option("-o", "--output", "output", type=GivenPath(dir_okay=False, path_type=Path), required=True, help="image file (.png, .pdf, .svg)")
@click.option("--until", type=float, default=None, help="simulate until this time (s from the first frame, the plots' clock and that of dynamics start/stop); default: the end of the timeline")
def plot(scene: Path, what: str, output: Path, until: float | None) -> None:
    """Simulate SCENE's dynamics and plot energy (per body, zero stated) or trajectories."""
    from motion.pipeline.bake import simulate_for, simulation_range
    from motion.pipeline.dynamics import simulate
    from motion.pipeline.dynamics.plots import FORMATS, plot_simulation
    from motion.pipeline.dynamics.world import shot_start
    from motion.pipeline.errors import UsageError
    from motion.pipeline.scene import load_scene

    if output.suffix.lower() not in FORMATS:
        raise UsageError(f"-o {output}: expected a .png, .pdf or .svg file")
    loaded = load_scene(scene)
    t_start, t_end = simulation_range(loaded)
    if until is not None:
        from motion.pipeline.scene.checks import MAX_SIMULATION_STEPS

        epoch = shot_start(loaded)
        t_end = epoch + until
        steps = (t_end - t_start) / loaded.scene.dynamics.step if math.isfinite(t_end) else math.inf
        if not (math.isfinite(t_end) and t_end > t_start and steps <= MAX_SIMULATION_STEPS):
            raise UsageError(f"--until {until}: expected a time after the simulation's start ({t_start - epoch:g} s from the first frame) "
                             f"that takes at most {MAX_SIMULATION_STEPS} steps of {loaded.scene.dynamics.step:g} s")
    # the whole timeline is what a render simulates: a simulation kept by one serves (bake/keep.py)
    sim = simulate_for(loaded) if until is None else None
    path = plot_simulation(loaded, sim if sim is not None else simulate(loaded, float(t_end), t_start), what, output)
    click.echo(f"wrote {path}")


commands = [plot]
