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
@click.option("--until", type=float, default=None, help="simulate until this time (s); default: the end of the timeline")
def plot(scene: Path, what: str, output: Path, until: float | None) -> None:
    """Simulate SCENE's dynamics and plot energy (per body, zero stated) or trajectories."""
    from motion.pipeline.bake import simulation_range
    from motion.pipeline.dynamics import simulate
    from motion.pipeline.dynamics.plots import FORMATS, plot_simulation
    from motion.pipeline.errors import UsageError
    from motion.pipeline.scene import load_scene

    if output.suffix.lower() not in FORMATS:
        raise UsageError(f"-o {output}: expected a .png, .pdf or .svg file")
    loaded = load_scene(scene)
    t_start, t_end = simulation_range(loaded)
    if until is not None:
        from motion.pipeline.scene.checks import MAX_SIMULATION_STEPS

        steps = (until - t_start) / loaded.scene.dynamics.step if math.isfinite(until) else math.inf
        if not (math.isfinite(until) and until > t_start and steps <= MAX_SIMULATION_STEPS):
            raise UsageError(f"--until {until}: expected a time after the simulation's start ({t_start:g} s) "
                             f"that takes at most {MAX_SIMULATION_STEPS} steps of {loaded.scene.dynamics.step:g} s")
        t_end = float(until)
    path = plot_simulation(loaded, simulate(loaded, t_end, t_start), what, output)
    click.echo(f"wrote {path}")


commands = [plot]
