"""`bake(loaded, frames)`: every frame's time and its N shutter sample times evaluated in
one vectorised call, checked, and sliced into one `BakedFrame` per frame."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..errors import UsageError
from .checks import check_budget, check_motion
from .records import BakedFrame, BakedFrames, BakedMotion
from .timing import sample_seconds, simulate_for

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene


def bake(loaded: "LoadedScene", frames: Sequence[int], simulation: Any | None = None) -> BakedMotion:
    """Evaluate `frames` (each at its time and at N times across its shutter).

    If the scene has dynamics and no `simulation` is given, it is simulated here, once,
    over `simulation_range` (the whole timeline, whatever the selection)."""
    from ..motion import evaluate, has_dynamics

    frames = [int(f) for f in frames]
    if not frames:
        raise UsageError("nothing to bake: the frame list is empty")
    scene = loaded.scene
    check_budget(loaded, len(frames))
    n = scene.render.shutter_samples
    frame_times, shutters, sample_times = sample_seconds(loaded, frames)
    everything = np.concatenate([frame_times, sample_times.ravel()])
    if simulation is None and has_dynamics(loaded):
        simulation = simulate_for(loaded, frames)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported by check_motion
        motion = evaluate(loaded, everything, simulation)
    check_motion(loaded, motion)
    baked = BakedFrames(frames, frame_times, shutters, sample_times, motion)
    shutter = scene.camera.shutter
    return BakedMotion(loaded.name, str(scene.timeline.rate), float(shutter.angle), shutter.position, baked)


def evaluate_frames(loaded: "LoadedScene", frames: Sequence[int], simulation: Any = None) -> Sequence[BakedFrame]:
    """The `BakedFrame`s of `frames` (simulating once here if the scene has dynamics and
    no `simulation` is given): what a worker renders. An empty selection gives []."""
    if not frames:
        return []
    return bake(loaded, frames, simulation).frames
