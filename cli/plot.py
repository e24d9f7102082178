"""`motion plot SCENE --what energy|trajectory -o FILE.png`: the pictures a TD looks at to
judge a simulation (energy over time; trajectories of the dynamics bodies)."""

from __future__ import annotations

from pathlib import Path

import click

from motion.pipeline.errors import UsageError


@click.command()
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--what", type=click.Choice(["energy", "trajectory"]), default="energy", show_default=True, help="energy over time, or body trajectories")
@click.option("-o", "--output", "output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="image file (.png, .pdf, .svg)")
@click.option("--until", type=float, default=None, help="simulate until this time (s); default: the end of the timeline")
def plot(scene: Path, what: str, output: Path, until: float | None) -> None:
    """Simulate SCENE's dynamics and plot energy or trajectories."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from motion.pipeline.dynamics import simulate
    from motion.pipeline.scene import load_scene

    if output.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise UsageError(f"-o {output}: expected a .png, .pdf or .svg file")
    loaded = load_scene(scene)
    timeline = loaded.scene.timeline.timeline()
    t_end = float(until) if until is not None else float(timeline.last + 1 - timeline.first) / float(timeline.fps) + float(timeline.first) / float(timeline.fps)
    t_start = min(0.0, t_end)
    sim = simulate(loaded, t_end, t_start)
    if sim.bodies is None and not sim.systems:
        raise UsageError(f"{scene}: the scene has no dynamics bodies or particle systems to plot")
    if what == "energy":
        fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
        for label, times, kinetic, potential in sim.energy():
            line = ax.plot(times, kinetic + potential, label=f"{label}: total")[0]
            ax.plot(times, kinetic, "--", color=line.get_color(), alpha=0.6, label=f"{label}: kinetic")
            ax.plot(times, potential, ":", color=line.get_color(), alpha=0.6, label=f"{label}: potential")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("energy (J)")
        ax.set_title(f"{loaded.name}: energy ({sim.integrator}, dt = {sim.step:g} s)")
        axes = [ax]
    else:
        # left: height over time (always meaningful); right: the side view (height against
        # horizontal distance) for bodies that really travel sideways. A body dropped
        # straight down moves ~1e-14 m sideways in floating point: plotting that against
        # height would draw noise, so such bodies are left out of the side view.
        fig, (ax_t, ax_s) = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100)
        times = np.linspace(sim.t_start, sim.t_end, 2000)
        up = -np.asarray(loaded.scene.dynamics.gravity, dtype=float)
        up = up / np.linalg.norm(up) if np.linalg.norm(up) > 0 else np.array([0.0, 1.0, 0.0])
        sideways = 0
        for name, pose in sim.sample(times).items():
            p = pose.translation
            line = ax_t.plot(times, p @ up, label=name)[0]
            horizontal = p - np.outer(p @ up, up)
            dist = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(horizontal, axis=0), axis=1))))
            if dist[-1] > 1e-3:
                ax_s.plot(dist, p @ up, color=line.get_color(), label=name)
                sideways += 1
        for name in sim.particle_systems:
            samples = sim.particles(name, times[:: max(1, len(times) // 200)])
            pts = samples.positions[samples.alive]
            if len(pts):
                ax_s.scatter(pts[:, 0], pts @ up, s=1, alpha=0.3, label=f"{name} (particles, x)")
                sideways += 1
        if not sideways:
            ax_s.text(0.5, 0.5, "no body moves sideways (> 1 mm)", ha="center", va="center", transform=ax_s.transAxes)
        ax_t.set_xlabel("time (s)")
        ax_t.set_ylabel("height (m)")
        ax_t.set_title(f"{loaded.name}: height over time")
        ax_s.set_xlabel("horizontal distance travelled (m)")
        ax_s.set_ylabel("height (m)")
        ax_s.set_title(f"{loaded.name}: side view")
        axes = [ax_t, ax_s]
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output)
    plt.close(fig)
    click.echo(f"wrote {output}")


commands = [plot]
