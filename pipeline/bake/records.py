"""The data contract from bake to worker: `BakedFrame` (what one worker needs to render one
frame) and `BakedMotion` (a bake: the frames plus what they were baked with).

Every time-dependent value is a `SceneMotion` under a named field: `at_frame` (one
sample, at the frame's time) and `across_shutter` (the `render.shutter_samples` N samples
from shutter open to close inclusive). No field stacks the two; no index rule.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, overload

from ..errors import FrameNotBakedError

if TYPE_CHECKING:
    import numpy as np

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


class BakedFrames(Sequence[BakedFrame]):
    """The frames of one bake, in the order baked, each made when asked for from the bake's
    own arrays: one `SceneMotion` over every frame time and then every shutter sample time
    (`bake()`'s single vectorised evaluation). A `BakedFrame` is a view of those arrays
    (`SceneMotion.take`), so holding the frames costs the arrays alone, not a record per
    frame (docs/bake-format.md has the figures).
    `by_number` is the same frames as a mapping by frame number."""

    def __init__(self, frames: Sequence[int], times: np.ndarray, shutters: np.ndarray, sample_times: np.ndarray, motion: "SceneMotion") -> None:
        self.numbers = [int(f) for f in frames]
        self.times = times  # [F]
        self.shutters = shutters  # [F, 2]
        self.sample_times = sample_times  # [F, N]
        self.motion = motion  # times: the F frame times, then F x N sample times
        self.by_number: Mapping[int, BakedFrame] = _ByNumber(self)
        self._index = {f: k for k, f in enumerate(self.numbers)}

    def __len__(self) -> int:
        return len(self.numbers)

    @overload
    def __getitem__(self, k: int) -> BakedFrame: ...

    @overload
    def __getitem__(self, k: slice) -> list[BakedFrame]: ...

    def __getitem__(self, k: int | slice) -> BakedFrame | list[BakedFrame]:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        count = len(self.numbers)
        if k < 0:
            k += count
        if not 0 <= k < count:
            raise IndexError(f"frame index {k} out of range for a bake of {count} frames")
        n = self.sample_times.shape[1]
        start = count + k * n
        return BakedFrame(
            frame=self.numbers[k],
            time=float(self.times[k]),
            shutter=(float(self.shutters[k, 0]), float(self.shutters[k, 1])),
            sample_times=self.sample_times[k],
            at_frame=self.motion.take(slice(k, k + 1)),
            across_shutter=self.motion.take(slice(start, start + n)),
        )

    def position(self, number: int) -> int | None:
        """Where frame `number` is in the bake's order (None if it is not baked)."""
        return self._index.get(number)


class _ByNumber(Mapping[int, BakedFrame]):
    """A bake's frames by frame number, each made on access (`BakedFrames.by_number`)."""

    def __init__(self, table: BakedFrames) -> None:
        self._table = table

    def __getitem__(self, number: int) -> BakedFrame:
        k = self._table.position(number)
        if k is None:
            raise KeyError(number)
        return self._table[k]

    def __iter__(self) -> Iterator[int]:
        return iter(self._table.numbers)

    def __len__(self) -> int:
        return len(self._table)


def by_number(frames: Sequence[BakedFrame]) -> Mapping[int, BakedFrame]:
    """`frames` by frame number: the table's own lazy view, or a dict of a plain list."""
    if isinstance(frames, BakedFrames):
        return frames.by_number
    return {f.frame: f for f in frames}


@dataclass(frozen=True)
class BakedMotion:
    """A bake: the scene's name, its frame rate (as text, e.g. "24000/1001"), the camera
    shutter it was baked with and the frames in the order baked."""

    scene: str
    fps: str
    shutter_angle: float
    shutter_position: str
    frames: Sequence[BakedFrame]  # a BakedFrames table from bake(), a list from a file

    @property
    def samples_per_frame(self) -> int:
        """N, the shutter samples of every frame (0 for an empty bake)."""
        return self.frames[0].samples if self.frames else 0

    def frame(self, number: int) -> BakedFrame:
        """The baked frame `number`; FrameNotBakedError if the bake does not hold it."""
        found = by_number(self.frames).get(number)
        if found is not None:
            return found
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
