"""The pictures a TD looks at to judge a simulation (`motion plot`): energy over time per
body, with its zero stated, and trajectories of the dynamics bodies.

Energy: one panel per dynamics body (kinetic, potential, total) when there are a few
bodies, else one line per body's total; particle systems and shared terms (springs,
gravity between bodies) are drawn as their group's totals. The potential's zero is the
plane through the world origin perpendicular to gravity ("height 0"), written on the plot.

Time runs on the dynamics clock (`CLOCK`: seconds from the first frame, 0 there whatever
its number), the clock of every `start`/`stop` of a dynamics block, so a body's `start: 0.5`
is at 0.5 on the plot.

Trajectory: height over time; the side view (height against horizontal distance) only
when some body or particle really moves sideways (a body dropped straight down moves
~1e-14 m sideways in floating point, which would draw noise in an empty-looking panel).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import UsageError
from ..write_policy import writing
from .world import shot_start

FORMATS = (".png", ".pdf", ".svg")
# the plots' time axis is the dynamics clock (world.shot_start): 0 at the first frame, the clock
# every `start`/`stop` of a dynamics block reads, not the scene's clock (41.7 s at frame 1001)
CLOCK = "time from the first frame (s; the clock of dynamics start/stop)"
PANELS_MAX = 6  # bodies drawn in panels of their own; more share one panel of totals


def plot_simulation(loaded: Any, sim: Any, what: str, output: str | Path) -> Path:
    """Draw `what` ("energy" or "trajectory") of `sim` (a dynamics Simulation of `loaded`)
    into `output` (.png, .pdf, .svg) and return its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    output = Path(output)
    if output.suffix.lower() not in FORMATS:
        raise UsageError(f"-o {output}: expected a .png, .pdf or .svg file")
    if sim.bodies is None and not sim.systems:
        raise UsageError(f"{loaded.path}: the scene has no dynamics bodies or particle systems to plot")
    fig = energy_figure(plt, loaded, sim) if what == "energy" else trajectory_figure(plt, loaded, sim)
    for ax in fig.axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    output.parent.mkdir(parents=True, exist_ok=True)
    try:
        with writing(output, "writing the plot", suffix=output.suffix) as tmp:  # a full disk: one line naming it, no partial file
            fig.savefig(tmp, format=output.suffix[1:].lower())
    finally:
        plt.close(fig)
    return output


def energy_figure(plt: Any, loaded: Any, sim: Any) -> Any:
    """Energy per body (kinetic, potential, total) and per particle system (totals)."""
    bodies = sim.body_energy()
    groups = [(label, t, k, p) for label, t, k, p in sim.energy() if label != "bodies"]
    shared = None
    if sim.bodies is not None and bodies:
        per_body_pot = sum(p - p[0] for _, _, _, p in bodies)  # (shift-free difference)
        shared_pot = (sim.bodies.potential - sim.bodies.potential[0]) - per_body_pot
        if np.max(np.abs(shared_pot)) > 1e-9 * max(1.0, float(np.max(np.abs(sim.bodies.potential)))):
            shared = (sim.bodies.times, shared_pot)
    panels = bodies if len(bodies) <= PANELS_MAX else []
    n = len(panels) + (1 if (len(bodies) > PANELS_MAX or groups or shared is not None) else 0)
    cols = min(3, max(1, n))
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.5 * cols, 3.4 * rows + 0.6), dpi=100, squeeze=False)
    flat = list(axes.ravel())
    epoch = shot_start(loaded)
    for ax, (name, t, k, p) in zip(flat, panels):
        t = t - epoch
        line = ax.plot(t, k + p, label="total")[0]
        ax.plot(t, k, "--", color=line.get_color(), alpha=0.7, label="kinetic")
        ax.plot(t, p, ":", color=line.get_color(), alpha=0.7, label="potential")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel(CLOCK)
        ax.set_ylabel("energy (J)")
    if n > len(panels):
        ax = flat[len(panels)]
        if len(bodies) > PANELS_MAX:
            for name, t, k, p in bodies:
                ax.plot(t - epoch, k + p, label=f"{name}: total")
        for label, t, k, p in groups:
            line = ax.plot(t - epoch, k + p, label=f"{label}: total")[0]
            ax.plot(t - epoch, k, "--", color=line.get_color(), alpha=0.6, label=f"{label}: kinetic")
        if shared is not None:
            ax.plot(shared[0] - epoch, shared[1], label="shared potential (springs, gravity between bodies), from its start")
        ax.set_title("totals", fontsize=10)
        ax.set_xlabel(CLOCK)
        ax.set_ylabel("energy (J)")
    for ax in flat[n:]:
        ax.set_visible(False)
    g = np.asarray(loaded.scene.dynamics.gravity, dtype=float)
    zero = "height 0 (the plane through the origin perpendicular to gravity)" if np.linalg.norm(g) > 0 else "none (no gravity)"
    fig.suptitle(f"{loaded.name}: energy ({sim.integrator}, dt = {sim.step:g} s); potential energy zero: {zero}", fontsize=10)
    return fig


def trajectory_figure(plt: Any, loaded: Any, sim: Any) -> Any:
    """Height over time; the side view only when something moves sideways."""
    times = np.linspace(sim.t_start, sim.t_end, 2000)
    up = -np.asarray(loaded.scene.dynamics.gravity, dtype=float)
    up = up / np.linalg.norm(up) if np.linalg.norm(up) > 0 else np.array([0.0, 1.0, 0.0])
    heights, side = [], []
    for name, pose in sim.sample(times).items():
        p = pose.translation
        horizontal = p - np.outer(p @ up, up)
        dist = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(horizontal, axis=0), axis=1))))
        heights.append((name, p @ up))
        if dist[-1] > 1e-3:
            side.append((name, dist, p @ up, False))
    for name in sim.particle_systems:
        samples = sim.particles(name, times[:: max(1, len(times) // 200)])
        pts = samples.positions[samples.alive]
        if len(pts):
            side.append((f"{name} (particles, x)", pts[:, 0], pts @ up, True))
    if side:
        fig, (ax_t, ax_s) = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100)
    else:
        fig, ax_t = plt.subplots(1, 1, figsize=(8, 4.5), dpi=100)
        ax_s = None
    colors = {}
    for name, h in heights:
        colors[name] = ax_t.plot(times - shot_start(loaded), h, label=name)[0].get_color()
    ax_t.set_xlabel(CLOCK)
    ax_t.set_ylabel("height (m)")
    ax_t.set_title(f"{loaded.name}: height over time" + ("" if side else " (no body moves sideways)"))
    if ax_s is not None:
        for name, x, h, scatter in side:
            if scatter:
                ax_s.scatter(x, h, s=1, alpha=0.3, label=name)
            else:
                ax_s.plot(x, h, color=colors.get(name), label=name)
        ax_s.set_xlabel("horizontal distance travelled (m)")
        ax_s.set_ylabel("height (m)")
        ax_s.set_title(f"{loaded.name}: side view")
    return fig
