"""Baked motion -> per-frame `FrameInput`s for the workers (poses at the frame time and at
the N samples across its shutter)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..scene.loader import LoadedScene
from .frame_renderer import FrameInput


def frame_times(loaded: LoadedScene, frame: int) -> tuple[float, tuple[float, float], np.ndarray]:
    """(frame time, shutter interval, [frame time, N sample times across the shutter])."""
    scene = loaded.scene
    tl = scene.timeline.timeline()
    shutter = tl.shutter(frame, scene.camera.shutter.angle, scene.camera.shutter.position)
    n = scene.render.shutter_samples
    t = float(tl.seconds(frame))
    samples = np.linspace(float(shutter[0]), float(shutter[1]), n)
    return t, (float(shutter[0]), float(shutter[1])), np.concatenate([[t], samples])


def inputs_from_motion(loaded: LoadedScene, frames: Sequence[int], motion: Any) -> list[FrameInput]:
    """Slice a `SceneMotion` evaluated at the concatenated times of `frames` (each frame's
    [frame time, N samples], in order) into one `FrameInput` per frame."""
    n1 = loaded.scene.render.shutter_samples + 1
    out = []
    light_keys = [light.name or f"light{i}" for i, light in enumerate(loaded.scene.lights)]
    for k, frame in enumerate(frames):
        sl = slice(k * n1, (k + 1) * n1)
        t, shutter, _ = frame_times(loaded, frame)
        objects = {name: (p.translation[sl], p.rotation[sl], p.scale[sl]) for name, p in motion.objects.items()}
        lights = {name: (p.translation[sl], p.rotation[sl], p.scale[sl]) for name, p in motion.lights.items() if name in light_keys}
        light_scalars = {name: {c: v[sl] for c, v in chans.items()} for name, chans in motion.light_scalars.items()}
        out.append(
            FrameInput(
                frame=frame,
                time=t,
                shutter=shutter,
                objects=objects,
                camera=(motion.camera.translation[sl], motion.camera.rotation[sl]),
                fov=np.asarray(motion.camera_scalars["fov"][sl], dtype=float),
                lights=lights,
                light_scalars=light_scalars,
            )
        )
    return out


def evaluate_frames(loaded: LoadedScene, frames: Sequence[int], simulation: Any = None) -> list[FrameInput]:
    """Evaluate the motion of `frames` (one vectorised call) and slice it per frame."""
    from ..motion import evaluate

    times = np.concatenate([frame_times(loaded, f)[2] for f in frames]) if frames else np.zeros(0)
    motion = evaluate(loaded, times, simulation)
    return inputs_from_motion(loaded, frames, motion)


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
    return h.hexdigest()
