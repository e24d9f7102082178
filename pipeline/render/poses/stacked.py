"""The renderer's view of one baked frame: every track stacked as [frame time, N shutter
samples] (`StackedFrame`, built by `stack_frame` alone from a `BakedFrame`), the shape the
first-frame cache, the scalar fallback and the slices read."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ...bake import BakedFrame


@dataclass(frozen=True)
class StackedFrame:
    """The renderer's own view of one `BakedFrame`, built by `stack_frame` alone: every
    track stacked as [frame time, N shutter samples], row 0 at the frame time and rows
    1..N across the shutter (`samples` = N)."""

    frame: int
    time: float
    shutter: tuple[float, float]
    samples: int
    objects: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]  # name -> (t [1+N,3], q [1+N,4], s [1+N,3])
    camera: tuple[np.ndarray, np.ndarray]  # (t [1+N,3], q [1+N,4])
    fov: np.ndarray  # [1+N]
    lights: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    light_scalars: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    vertices: dict[str, np.ndarray] = field(default_factory=dict)  # deforming meshes [1+N, V, 3], object space
    ortho_width: np.ndarray | None = None  # [1+N], orthographic cameras
    particles: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # (positions [1+N, n, 3], alive [1+N, n])
    stretches: dict[str, np.ndarray] = field(default_factory=dict)  # objects whose stretch is not diagonal: S [1+N, 3, 3]
    _stacks: dict[tuple[str, ...], tuple[np.ndarray, ...]] = field(default_factory=dict, repr=False, compare=False)

    def tracks(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracks of the objects `names` in one stack each: translation [M, 1+N, 3],
        rotation [M, 1+N, 4] and scale [M, 1+N, 3] (one gather per frame and set of names:
        the first-frame cache reads every mover's poses from it, never mover by mover)."""
        key = tuple(names)
        if key not in self._stacks:
            rows = self.samples + 1
            self._stacks[key] = tuple(
                np.array([self.objects[n][c] for n in key], dtype=float).reshape(len(key), rows, width) for c, width in ((0, 3), (1, 4), (2, 3)))
        t, q, s = self._stacks[key]
        return t, q, s

    def stretch_at_frame(self, names: Sequence[str]) -> np.ndarray:
        """Each object's stretch at the frame's time [M, 3, 3]: diag(scale), or the full
        symmetric S under a non-uniform parent scale (`instant.rest_frame`, stacked)."""
        out = self.tracks(names)[2][:, 0, :, None] * np.eye(3)
        if self.stretches:  # (few objects: a loop over them, not over every mover)
            row = {n: k for k, n in enumerate(names)}
            for name, stretch in self.stretches.items():
                if name in row:
                    out[row[name]] = stretch[0]
        return out


def stack_frame(frame: BakedFrame) -> StackedFrame:
    """`frame.at_frame` followed by `frame.across_shutter`, track by track."""
    at, across = frame.at_frame, frame.across_shutter

    def pose(p: Any, q: Any) -> tuple[np.ndarray, ...]:
        return tuple(np.concatenate([x, y]) for x, y in zip(p[:3], q[:3]))

    def stretch(p: Any, q: Any) -> np.ndarray | None:
        if p.stretch_offdiag is None and q.stretch_offdiag is None:
            return None
        return np.concatenate([p.stretch(), q.stretch()])

    stretches = {n: stretch(p, across.objects[n]) for n, p in at.objects.items()}

    fov = np.concatenate([at.camera_scalars["fov"], across.camera_scalars["fov"]])
    ortho = np.concatenate([at.camera_scalars["ortho_width"], across.camera_scalars["ortho_width"]]) if "ortho_width" in at.camera_scalars else None
    return StackedFrame(
        frame=frame.frame,
        time=float(frame.time),
        shutter=(float(frame.shutter[0]), float(frame.shutter[1])),
        samples=len(across.times),
        objects={n: pose(p, across.objects[n]) for n, p in at.objects.items()},  # type: ignore[misc]
        camera=pose(at.camera, across.camera)[:2],  # type: ignore[arg-type]
        fov=np.asarray(fov, dtype=float),
        ortho_width=None if ortho is None else np.asarray(ortho, dtype=float),
        lights={n: pose(p, across.lights[n]) for n, p in at.lights.items()},  # type: ignore[misc]
        light_scalars={n: {c: np.concatenate([v, across.light_scalars[n][c]]) for c, v in d.items()} for n, d in at.light_scalars.items()},
        vertices={n: np.concatenate([v, across.vertices[n]]) for n, v in at.vertices.items()},
        particles={
            n: (np.concatenate([p.positions, across.particles[n].positions]), np.concatenate([p.alive, across.particles[n].alive]))
            for n, p in at.particles.items()
        },
        stretches={n: s for n, s in stretches.items() if s is not None},
    )
