"""Baked motion -> per-frame `FrameInput`s for the workers (poses at the frame time and at
the N samples across its shutter)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..scene.loader import LoadedScene
from .frame_renderer import FrameInput


def inputs_from_baked(baked: Any) -> list[FrameInput]:
    """One `FrameInput` per baked frame: index 0 is the frame time, 1..N the shutter samples."""
    out = []
    for bf in baked.frames:
        motion = _concat(bf.at_frame, bf.motion)
        out.append(
            FrameInput(
                frame=bf.frame,
                time=float(bf.time),
                shutter=(float(bf.shutter[0]), float(bf.shutter[1])),
                objects={n: (p.translation, p.rotation, p.scale) for n, p in motion.objects.items()},
                camera=(motion.camera.translation, motion.camera.rotation),
                fov=np.asarray(motion.camera_scalars["fov"], dtype=float),
                ortho_width=np.asarray(motion.camera_scalars["ortho_width"], dtype=float) if "ortho_width" in motion.camera_scalars else None,
                lights={n: (p.translation, p.rotation, p.scale) for n, p in motion.lights.items()},
                light_scalars=motion.light_scalars,
                vertices=motion.vertices,
                particles={n: (np.asarray(v.positions), np.asarray(v.alive)) for n, v in motion.particles.items()},
            )
        )
    return out


def _concat(a: Any, b: Any) -> Any:
    """SceneMotion at [a's times, b's times] (a: the frame time, b: the shutter samples)."""
    from ..motion import Pose, SceneMotion

    def pose(p: Any, q: Any) -> Any:
        return Pose(np.concatenate([p.translation, q.translation]), np.concatenate([p.rotation, q.rotation]), np.concatenate([p.scale, q.scale]))

    particles = {}
    for name, pa in a.particles.items():
        pb = b.particles[name]
        particles[name] = pa._replace(positions=np.concatenate([pa.positions, pb.positions]), alive=np.concatenate([pa.alive, pb.alive]))
    return SceneMotion(
        times=np.concatenate([a.times, b.times]),
        objects={k: pose(v, b.objects[k]) for k, v in a.objects.items()},
        camera=pose(a.camera, b.camera),
        camera_scalars={k: np.concatenate([v, b.camera_scalars[k]]) for k, v in a.camera_scalars.items()},
        lights={k: pose(v, b.lights[k]) for k, v in a.lights.items()},
        light_scalars={k: {n: np.concatenate([v, b.light_scalars[k][n]]) for n, v in d.items()} for k, d in a.light_scalars.items()},
        vertices={k: np.concatenate([v, b.vertices[k]]) for k, v in a.vertices.items()},
        particles=particles,
    )


def evaluate_frames(loaded: LoadedScene, frames: Sequence[int], simulation: Any = None) -> list[FrameInput]:
    """Bake `frames` (simulating once here if the scene has dynamics) into FrameInputs."""
    from ..bake import bake

    return inputs_from_baked(bake(loaded, frames, simulation))


def fingerprint(inputs: Sequence[FrameInput]) -> str:
    """A stable digest of the poses (what --resume compares as the motion hash)."""
    import hashlib

    h = hashlib.sha256()
    for fi in inputs:
        h.update(str(fi.frame).encode())
        for name in sorted(fi.objects):
            for a in fi.objects[name]:
                h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        for a in fi.camera:
            h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(fi.fov, dtype=np.float64).tobytes())
        for name in sorted(fi.vertices):
            h.update(np.ascontiguousarray(fi.vertices[name], dtype=np.float64).tobytes())
        for name in sorted(fi.particles):
            for a in fi.particles[name]:
                h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()
