"""Bake: evaluated motion per frame, across each frame's shutter (docs/bake-format.md).

`bake(loaded, frames)` evaluates every frame's time and its N shutter sample times in one
vectorised call and slices the result per frame. `write_baked` / `read_baked` store it
as JSON (readable; rigid transforms and scalars) or NPZ (everything, vertex arrays and
particles included). What the farm ships to workers is this small, plain data.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .errors import MotionError, UsageError

if TYPE_CHECKING:
    from .motion import SceneMotion
    from .scene.loader import LoadedScene

FORMAT = "motion-bake"
VERSION = 1


class BakeFileError(MotionError):
    """A baked-motion file cannot be written or read back (path, format, layout)."""


@dataclass(frozen=True)
class BakedFrame:
    """One frame: its number, time (s), shutter [open, close] (s), the N sample times
    across the shutter (open..close inclusive), the motion at those sample times, and the
    motion at the frame time itself (`at_frame`, one sample)."""

    frame: int
    time: float
    shutter: tuple[float, float]
    sample_times: np.ndarray
    motion: "SceneMotion"
    at_frame: "SceneMotion"


@dataclass(frozen=True)
class BakedMotion:
    scene: str
    fps: str
    shutter_angle: float
    shutter_position: str
    frames: list[BakedFrame]

    def frame(self, number: int) -> BakedFrame:
        for f in self.frames:
            if f.frame == number:
                return f
        raise KeyError(f"frame {number} is not in this bake ({self.frames[0].frame}..{self.frames[-1].frame})")


def frame_sample_times(loaded: "LoadedScene", frame: int) -> tuple[Fraction, tuple[Fraction, Fraction], list[Fraction]]:
    """Exact frame time, shutter interval and the `render.shutter_samples` times across it."""
    scene = loaded.scene
    timeline = scene.timeline.timeline()
    shutter = scene.camera.shutter
    t_open, t_close = timeline.shutter(frame, Fraction(shutter.angle), shutter.position)
    n = scene.render.shutter_samples
    samples = [t_open + (t_close - t_open) * k / (n - 1) for k in range(n)]
    return timeline.seconds(frame), (t_open, t_close), samples


def simulation_range(loaded: "LoadedScene", frames: Sequence[int] = ()) -> tuple[float, float]:
    """The time range (s) the scene's dynamics are simulated over: the whole timeline,
    from min(0, the first frame's shutter open) to the last frame's shutter close, never
    the selection. A frame's motion then does not depend on which other frames were
    selected (the fixed step grid starts at the same time and no run is cut short next to
    it; emitters spawn the same particles). Frames outside the timeline (the API allows
    them) widen the range."""
    timeline = loaded.scene.timeline.timeline()
    ends = [timeline.first, timeline.last] + ([min(frames), max(frames)] if len(frames) else [])
    lo, hi = min(ends), max(ends)
    (t_lo, (open_lo, _), _), (t_hi, (_, close_hi), _) = frame_sample_times(loaded, lo), frame_sample_times(loaded, hi)
    return min(0.0, float(min(t_lo, open_lo))), float(max(t_hi, close_hi))


def simulate_for(loaded: "LoadedScene", frames: Sequence[int] = (), on_progress: Any = None) -> Any | None:
    """The scene's dynamics simulated over `simulation_range` (None without dynamics).
    What `bake` runs when it is given no simulation, and what the farm runs once before
    sharding. `on_progress(t, t_start, t_end)` is called as the simulation advances."""
    from .motion import has_dynamics

    if not has_dynamics(loaded):
        return None
    from .dynamics import simulate

    t_start, t_end = simulation_range(loaded, frames)
    if on_progress is None:
        return simulate(loaded, t_end=t_end, t_start=t_start)
    return simulate(loaded, t_end=t_end, t_start=t_start, on_progress=on_progress)


def bake(loaded: "LoadedScene", frames: Sequence[int], simulation: Any | None = None) -> BakedMotion:
    """Evaluate `frames` (each at its time and at N times across its shutter).

    If the scene has dynamics and no `simulation` is given, it is simulated here, once,
    over `simulation_range` (the whole timeline, whatever the selection)."""
    from .motion import evaluate, has_dynamics

    frames = [int(f) for f in frames]
    if not frames:
        raise UsageError("nothing to bake: the frame list is empty")
    scene = loaded.scene
    n = scene.render.shutter_samples
    exact = [frame_sample_times(loaded, f) for f in frames]
    frame_times = np.array([float(t) for t, _, _ in exact])
    sample_times = np.array([[float(s) for s in samples] for _, _, samples in exact])
    everything = np.concatenate([frame_times, sample_times.ravel()])
    if simulation is None and has_dynamics(loaded):
        simulation = simulate_for(loaded, frames)
    motion = evaluate(loaded, everything, simulation)
    count = len(frames)
    baked = []
    for k, (f, (_, (t_open, t_close), _)) in enumerate(zip(frames, exact)):
        start = count + k * n
        baked.append(
            BakedFrame(
                frame=f,
                time=float(frame_times[k]),
                shutter=(float(t_open), float(t_close)),
                sample_times=sample_times[k],
                motion=motion.take(slice(start, start + n)),
                at_frame=motion.take(slice(k, k + 1)),
            )
        )
    shutter = scene.camera.shutter
    return BakedMotion(loaded.name, str(scene.timeline.rate), float(shutter.angle), shutter.position, baked)


# --- files --------------------------------------------------------------------------------

_POSE_FIELDS = ("translation", "rotation", "scale")


def _motion_arrays(motion: "SceneMotion", prefix: str, with_heavy: bool) -> dict[str, np.ndarray]:
    """Flatten one SceneMotion into `prefix/...` keys (see docs/bake-format.md)."""
    out: dict[str, np.ndarray] = {}
    for group in ("objects", "lights"):
        for name, pose in getattr(motion, group).items():
            for fld, arr in zip(_POSE_FIELDS, pose):
                out[f"{prefix}/{group}/{name}/{fld}"] = arr
    for fld, arr in zip(_POSE_FIELDS, motion.camera):
        out[f"{prefix}/camera/{fld}"] = arr
    for name, arr in motion.camera_scalars.items():
        out[f"{prefix}/camera_scalars/{name}"] = arr
    for light, scalars in motion.light_scalars.items():
        for name, arr in scalars.items():
            out[f"{prefix}/light_scalars/{light}/{name}"] = arr
    if with_heavy:
        for name, arr in motion.vertices.items():
            out[f"{prefix}/vertices/{name}"] = arr
        for name, ps in motion.particles.items():
            out[f"{prefix}/particles/{name}/positions"] = np.asarray(ps.positions)
            out[f"{prefix}/particles/{name}/alive"] = np.asarray(ps.alive)
            out[f"{prefix}/particles/{name}/ids"] = np.asarray(ps.ids)
    return out


def _meta(baked: BakedMotion) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "scene": baked.scene,
        "fps": baked.fps,
        "shutter": {"angle": baked.shutter_angle, "position": baked.shutter_position},
        "samples_per_frame": int(len(baked.frames[0].sample_times)),
    }


def write_baked(baked: BakedMotion, path: str | Path) -> Path:
    """Write `.json` or `.npz` (by extension) atomically; returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".json", ".npz"):
        raise BakeFileError(f"{path}: unknown extension {path.suffix!r} (use .json or .npz)")
    if not path.parent.exists():
        raise BakeFileError(f"{path}: directory {path.parent} does not exist")
    tmp = path.with_name(f".{path.name}.tmp{suffix}")
    try:
        if suffix == ".json":
            doc = _meta(baked)
            frames = []
            for f in baked.frames:
                frames.append(
                    {
                        "frame": f.frame,
                        "time": f.time,
                        "shutter": list(f.shutter),
                        "sample_times": f.sample_times.tolist(),
                        "at_frame": _nest({k: v[0] for k, v in _motion_arrays(f.at_frame, "m", False).items()}),
                        "samples": _nest(_motion_arrays(f.motion, "m", False)),
                    }
                )
            doc["frames"] = frames
            tmp.write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")
        else:
            arrays: dict[str, np.ndarray] = {
                "meta": np.array(json.dumps(_meta(baked))),
                "frames": np.array([f.frame for f in baked.frames], dtype=np.int64),
                "times": np.array([f.time for f in baked.frames]),
                "shutter": np.array([f.shutter for f in baked.frames]),
                "sample_times": np.stack([f.sample_times for f in baked.frames]),
            }
            per_frame = [_motion_arrays(f.motion, "samples", True) for f in baked.frames]
            at_frame = [_motion_arrays(f.at_frame, "at_frame", False) for f in baked.frames]
            for rows in (per_frame, at_frame):
                for key in rows[0]:
                    stacked = np.stack([r[key] for r in rows])
                    arrays[key] = stacked[:, 0] if key.startswith("at_frame/") else stacked
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise BakeFileError(f"{path}: cannot write: {exc}") from None
    return path


def _nest(flat: dict[str, np.ndarray]) -> dict[str, Any]:
    """{'m/objects/a/translation': arr} -> {'objects': {'a': {'translation': [...]}}}."""
    out: dict[str, Any] = {}
    for key, arr in flat.items():
        parts = key.split("/")[1:]
        node = out
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = np.asarray(arr).tolist()
    return out


def read_baked(path: str | Path) -> dict[str, Any]:
    """Read a baked file back as plain data: the meta fields plus `frames`, and for NPZ
    every array by its key (docs/bake-format.md). Raises BakeFileError on a bad file."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text(encoding="utf-8"))
        else:
            with np.load(path, allow_pickle=False) as data:
                doc = json.loads(str(data["meta"]))
                doc["arrays"] = {k: data[k] for k in data.files if k != "meta"}
    except (OSError, ValueError, KeyError) as exc:
        raise BakeFileError(f"{path}: not a readable baked-motion file: {exc}") from None
    if doc.get("format") != FORMAT:
        raise BakeFileError(f"{path}: not a baked-motion file (format {doc.get('format')!r})")
    if doc.get("version") != VERSION:
        raise BakeFileError(f"{path}: baked-motion version {doc.get('version')!r}; this build reads {VERSION}")
    return doc


def summary(baked: BakedMotion) -> dict[str, Any]:
    """Counts for a one-line report."""
    first = baked.frames[0].motion
    return {
        "frames": len(baked.frames),
        "samples_per_frame": int(len(baked.frames[0].sample_times)),
        "objects": len(first.objects),
        "lights": len(first.lights),
        "deforming": len(first.vertices),
        "particle_systems": len(first.particles),
    }


__all__ = ["BakeFileError", "BakedFrame", "BakedMotion", "bake", "frame_sample_times", "read_baked", "simulate_for", "simulation_range", "summary", "write_baked"]
