"""Bake: evaluated motion per frame, across each frame's shutter (docs/bake-format.md).

`bake(loaded, frames)` evaluates every frame's time and its N shutter sample times in one
vectorised call and slices the result per frame. `write_baked` / `read_baked` store it
as JSON (readable; rigid transforms and scalars) or NPZ (everything, vertex arrays and
particles included). What the farm ships to workers is this small, plain data.
"""

from __future__ import annotations

import json
import zipfile
import zlib
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
    _check_budget(loaded, len(frames))
    n = scene.render.shutter_samples
    exact = [frame_sample_times(loaded, f) for f in frames]
    frame_times = np.array([float(t) for t, _, _ in exact])
    sample_times = np.array([[float(s) for s in samples] for _, _, samples in exact])
    everything = np.concatenate([frame_times, sample_times.ravel()])
    if simulation is None and has_dynamics(loaded):
        simulation = simulate_for(loaded, frames)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported by check_motion
        motion = evaluate(loaded, everything, simulation)
    check_motion(loaded, motion)
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


MAX_BAKE_BYTES = 2 * 1024**3  # a baked-motion file on disk
MAX_BAKE_ARRAY_BYTES = 4 * 1024**3  # its arrays once decompressed (NPZ)


def read_baked(path: str | Path) -> dict[str, Any]:
    """Read a baked file back as plain data: the meta fields plus `frames`, and for NPZ
    every array by its key (docs/bake-format.md). Raises BakeFileError on a bad file.

    Bounded like a scene: a regular file of at most MAX_BAKE_BYTES, JSON nesting and
    numbers as Python's json module allows (a RecursionError is a bad file), NPZ arrays
    declared no larger than MAX_BAKE_ARRAY_BYTES in all before any is decompressed, and
    no pickled objects."""
    from .errors import InputFileError
    from .scene.loader import open_bounded

    path = Path(path)
    try:
        fh = open_bounded(path, MAX_BAKE_BYTES, "baked-motion file")
    except InputFileError as exc:
        raise BakeFileError(f"{path}: {exc.reason}") from None
    try:
        with fh:
            head = fh.read(6)
            fh.seek(0)
            if not head:
                raise BakeFileError(f"{path}: the baked-motion file is empty")
            if path.suffix.lower() == ".json" or head[:1] in (b"{", b"[", b" ", b"\n"):
                doc = json.loads(fh.read().decode("utf-8"))
            elif head[:4] == b"PK\x03\x04":
                doc = _read_npz(fh, path)
            else:
                raise BakeFileError(f"{path}: not a baked-motion file (neither JSON nor NPZ)")
    except BakeFileError:
        raise
    except (OSError, ValueError, KeyError, EOFError, RecursionError, TypeError, UnicodeDecodeError, zipfile.BadZipFile, zlib.error) as exc:
        raise BakeFileError(f"{path}: not a readable baked-motion file: {type(exc).__name__}: {str(exc)[:200]}") from None
    if not isinstance(doc, dict):
        raise BakeFileError(f"{path}: not a baked-motion file (the top level is a {type(doc).__name__}, not an object)")
    if doc.get("format") != FORMAT:
        raise BakeFileError(f"{path}: not a baked-motion file (format {str(doc.get('format'))[:40]!r})")
    if doc.get("version") != VERSION:
        raise BakeFileError(f"{path}: baked-motion version {str(doc.get('version'))[:40]!r}; this build reads {VERSION}")
    return doc


def _read_npz(fh: Any, path: Path) -> dict[str, Any]:
    """An NPZ bake: each member's header is read first and the declared sizes summed, so a
    small file cannot decompress into gigabytes; object arrays (pickles) are refused."""
    with zipfile.ZipFile(fh) as zf:
        declared = 0
        for info in zf.infolist():
            with zf.open(info) as member:
                version = np.lib.format.read_magic(member)
                read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                shape, _, dtype = read_header(member)  # the header only, nothing decompressed
            if dtype.hasobject:
                raise BakeFileError(f"{path}: array {info.filename!r} holds Python objects (refused)")
            declared += int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
            if declared > MAX_BAKE_ARRAY_BYTES:
                raise BakeFileError(f"{path}: its arrays declare more than {MAX_BAKE_ARRAY_BYTES} bytes (the limit)")
    fh.seek(0)
    with np.load(fh, allow_pickle=False) as data:
        if "meta" not in data.files:
            raise BakeFileError(f"{path}: not a baked-motion file (no 'meta' array)")
        doc = json.loads(str(data["meta"]))
        if isinstance(doc, dict):
            doc["arrays"] = {k: data[k] for k in data.files if k != "meta"}
    return doc


def _check_budget(loaded: "LoadedScene", frames: int) -> None:
    """Refuse a bake whose particle positions would not fit the budget (checks.py)."""
    from .errors import SceneError
    from .scene.checks import bake_budget_problems

    problems = bake_budget_problems(loaded.scene, loaded.source, frames)
    if problems:
        raise SceneError(problems)


# --- guards: every evaluated pose and every loaded bake is finite, rotations are unit ------

UNIT_TOLERANCE = 1e-6  # | |q| - 1 | allowed for a rotation quaternion


def pose_problem(translation: Any, rotation: Any, scale: Any, times: Any) -> str | None:
    """What is wrong with one pose track ([T, 3], [T, 4], [T, 3] at `times` [T]), or None:
    a wrong shape, a non-finite translation, rotation or scale, a rotation that is not a
    unit quaternion. The message names the channel and the first time at fault."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    for channel, arr, width in (("translation", translation, 3), ("rotation", rotation, 4), ("scale", scale, 3)):
        a = np.asarray(arr)
        if a.dtype.kind not in "fiu" or a.ndim != 2 or a.shape != (times.size, width):
            return f"{channel} has shape {a.shape} ({a.dtype}), expected [{times.size}, {width}] numbers"
        bad = ~np.isfinite(a.astype(np.float64)).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            return f"{channel} is not finite at t = {times[k]:.6g} s ({', '.join(f'{v:g}' for v in a[k])})"
    norm = np.linalg.norm(np.asarray(rotation, dtype=np.float64), axis=1)
    off = np.abs(norm - 1.0) > UNIT_TOLERANCE
    if off.any():
        k = int(np.argmax(off))
        return f"rotation is not a unit quaternion at t = {times[k]:.6g} s (|q| = {norm[k]:.6g})"
    return None


def scalar_problem(name: str, arr: Any, times: Any) -> str | None:
    """A scalar or colour channel ([T] or [T, C]) that is not finite, or None."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    a = np.asarray(arr)
    if a.dtype.kind not in "fiu" or a.ndim not in (1, 2) or a.shape[0] != times.size:
        return f"{name} has shape {a.shape} ({a.dtype}), expected [{times.size}] or [{times.size}, C] numbers"
    bad = ~np.isfinite(a.astype(np.float64).reshape(times.size, -1)).all(axis=1)
    if bad.any():
        return f"{name} is not finite at t = {times[int(np.argmax(bad))]:.6g} s"
    return None


def check_motion(loaded: "LoadedScene", motion: "SceneMotion") -> None:
    """Refuse evaluated motion with a non-finite value or a non-unit rotation (an
    overflowing expression or generator would otherwise make an object vanish): SceneError
    at the owner's `motion` block, naming the object, the channel and the time."""
    from .errors import SceneError

    scene = loaded.scene
    times = motion.times
    owners: list[tuple[tuple[Any, ...], str, Any]] = [(("camera", "motion"), "camera", motion.camera)]
    index = {o.name: i for i, o in enumerate(scene.objects)}
    owners += [(("objects", index.get(n, 0), "motion"), f"object '{n}'", p) for n, p in motion.objects.items()]
    light_index = {(light.name or f"light{i}"): i for i, light in enumerate(scene.lights)}
    owners += [(("lights", light_index.get(n, 0), "motion"), f"light '{n}'", p) for n, p in motion.lights.items()]
    problems = []
    for loc, who, pose in owners:
        why = pose_problem(*pose, times)
        if why is not None:
            problems.append(loaded.source.problem(loc, f"{who}: {why}"))
    scalars = [(("camera", "motion"), "camera", name, arr) for name, arr in motion.camera_scalars.items()]
    scalars += [(("lights", light_index.get(n, 0), "motion"), f"light '{n}'", c, arr) for n, d in motion.light_scalars.items() for c, arr in d.items()]
    for loc, who, name, arr in scalars:
        why = scalar_problem(name, arr, times)
        if why is not None:
            problems.append(loaded.source.problem(loc, f"{who}: {why}"))
    for name, verts in motion.vertices.items():
        why = scalar_problem("vertices", np.asarray(verts).reshape(len(times), -1), times)
        if why is not None:
            problems.append(loaded.source.problem(("objects", index.get(name, 0), "deform"), f"object '{name}': {why}"))
    for name, ps in motion.particles.items():
        pos = np.asarray(ps.positions)
        if pos.size and not np.isfinite(pos).all():
            k = int(np.argmax(~np.isfinite(pos.reshape(len(times), -1)).all(axis=1)))
            problems.append(loaded.source.problem(("objects", index.get(name, 0), "emitter"), f"particles '{name}': positions are not finite at t = {times[k]:.6g} s"))
    if problems:
        raise SceneError(problems)


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
