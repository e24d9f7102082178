"""When a frame is sampled (its time, shutter and the N sample times) and the one time
range the scene's dynamics are simulated over. The bake and the farm both use these, so
every shard and every frame selection simulates the same range."""

from __future__ import annotations

from fractions import Fraction
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene


def sample_seconds(loaded: "LoadedScene", frames: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """When each frame is sampled, as float64 arrays: frame times [F], shutters [F, 2]
    ([open, close]) and the `render.shutter_samples` times across each shutter [F, N]
    (open..close inclusive). Each value is the exact rational time (Fractions from the
    timeline) rounded once to the nearest float, the same bits as `float()` of the
    Fraction; the samples are computed with integer arithmetic, so a bake of a long shot
    does not pay for 10^4 Fraction objects."""
    scene = loaded.scene
    timeline = scene.timeline.timeline()
    angle, position = Fraction(scene.camera.shutter.angle), scene.camera.shutter.position
    n = scene.render.shutter_samples
    times = np.empty(len(frames))
    shutters = np.empty((len(frames), 2))
    samples = np.empty((len(frames), n))
    for i, f in enumerate(frames):
        t_open, t_close = timeline.shutter(f, angle, position)
        times[i] = float(timeline.seconds(f))
        shutters[i] = float(t_open), float(t_close)
        # t_open + (t_close - t_open) * k / (n - 1) over one common denominator; int / int
        # is correctly rounded, as float(Fraction) is
        a, b, c, d = t_open.numerator, t_open.denominator, t_close.numerator, t_close.denominator
        base, step, den = a * d * (n - 1), c * b - a * d, b * d * (n - 1)
        samples[i] = [(base + step * k) / den for k in range(n)]
    return times, shutters, samples


def simulation_range(loaded: "LoadedScene", frames: Sequence[int] = ()) -> tuple[float, float]:
    """The time range (s) the scene's dynamics are simulated over: the whole timeline,
    from the first frame's shutter open (the shot starts there, whatever its frame number:
    a frame-1001 shot does not simulate 41 s before its first frame) to the last frame's
    shutter close, never the selection. A frame's motion then does not depend on which other frames were
    selected (the fixed step grid starts at the same time and no run is cut short next to
    it; emitters spawn the same particles). Frames outside the timeline (the API allows
    them) widen the range."""
    timeline = loaded.scene.timeline.timeline()
    ends = [timeline.first, timeline.last] + ([min(frames), max(frames)] if len(frames) else [])
    lo, hi = min(ends), max(ends)
    times, shutters, _ = sample_seconds(loaded, [lo, hi])
    return float(min(times[0], shutters[0, 0])), float(max(times[1], shutters[1, 1]))


def simulate_for(loaded: "LoadedScene", frames: Sequence[int] = (), on_progress: Any = None) -> Any | None:
    """The scene's dynamics simulated over `simulation_range` (None without dynamics), or
    the simulation an earlier run kept for the same dynamics inputs (keep.py). What `bake`
    runs when it is given no simulation, and what the farm runs once before sharding. `on_progress(t, t_start, t_end)` is called as the simulation advances."""
    from ..motion import has_dynamics

    if not has_dynamics(loaded):
        return None
    from ..dynamics import simulate

    from .keep import kept

    t_start, t_end = simulation_range(loaded, frames)
    if on_progress is None:
        return kept(loaded, t_start, t_end, lambda: simulate(loaded, t_end=t_end, t_start=t_start))
    return kept(loaded, t_start, t_end, lambda: simulate(loaded, t_end=t_end, t_start=t_start, on_progress=on_progress))
