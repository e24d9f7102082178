"""The data contract from bake to worker: `BakedFrame` (what one worker needs to render one
frame) and `BakedMotion` (a bake: the frames plus what they were baked with).

Every time-dependent value is a `SceneMotion` under a named field: `at_frame` (one
sample, at the frame's time) and `across_shutter` (the `render.shutter_samples` N samples
from shutter open to close inclusive). No field stacks the two; no index rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import FrameNotBakedError

if TYPE_CHECKING:
    from ..motion import SceneMotion


@dataclass(frozen=True)
class BakedFrame:
    """One frame as a worker renders it: its number, time (s), shutter [open, close] (s),
    the N sample times across the shutter (open..close inclusive, [N]), the motion at the
    frame time (`at_frame`, times [1]) and at the N sample times (`across_shutter`,
    times [N]). Small, plain and picklable."""

    frame: int
    time: float
    shutter: tuple[float, float]
    sample_times: np.ndarray
    at_frame: "SceneMotion"
    across_shutter: "SceneMotion"

    @property
    def samples(self) -> int:
        """N, the number of motion samples across the shutter."""
        return int(len(self.sample_times))


@dataclass(frozen=True)
class BakedMotion:
    """A bake: the scene's name, its frame rate (as text, e.g. "24000/1001"), the camera
    shutter it was baked with and the frames in the order baked."""

    scene: str
    fps: str
    shutter_angle: float
    shutter_position: str
    frames: list[BakedFrame]

    @property
    def samples_per_frame(self) -> int:
        """N, the shutter samples of every frame (0 for an empty bake)."""
        return self.frames[0].samples if self.frames else 0

    def frame(self, number: int) -> BakedFrame:
        """The baked frame `number`; FrameNotBakedError if the bake does not hold it."""
        for f in self.frames:
            if f.frame == number:
                return f
        held = f"{self.frames[0].frame}..{self.frames[-1].frame}" if self.frames else "none"
        raise FrameNotBakedError(f"frame {number} is not in this bake (it holds {held})")


def summary(baked: BakedMotion) -> dict[str, Any]:
    """Counts for a one-line report."""
    first = baked.frames[0].across_shutter
    return {
        "frames": len(baked.frames),
        "samples_per_frame": baked.samples_per_frame,
        "objects": len(first.objects),
        "lights": len(first.lights),
        "deforming": len(first.vertices),
        "particle_systems": len(first.particles),
    }
