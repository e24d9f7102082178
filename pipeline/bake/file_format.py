"""Bake files: `write_baked` stores a BakedMotion as JSON (readable; rigid transforms
and scalars) or NPZ (also vertex arrays and particles, at the frame and across the shutter), and
`read_baked` is the one reader: it returns the same typed, validated records
(docs/bake-format.md)."""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path
from collections.abc import Collection
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import BakeFileError
from ..write_policy import writing
from ..timeline import MAX_FRAME_NUMBER, MAX_FRAMES
from .checks import motion_problems
from .records import BakedFrame, BakedMotion

if TYPE_CHECKING:
    from ..motion import SceneMotion

FORMAT = "motion-bake"
VERSION = 1

# --- files --------------------------------------------------------------------------------

_POSE_FIELDS = ("translation", "rotation", "scale")
# the stretch's off-diagonal terms (S_xy, S_xz, S_yz), written only where a pose has them
_STRETCH_FIELD = "stretch"


def _motion_arrays(motion: "SceneMotion", prefix: str, with_heavy: bool) -> dict[str, np.ndarray]:
    """Flatten one SceneMotion into `prefix/...` keys (see docs/bake-format.md)."""
    out: dict[str, np.ndarray] = {}
    for group in ("objects", "lights"):
        for name, pose in getattr(motion, group).items():
            out.update(_pose_arrays(pose, f"{prefix}/{group}/{name}"))
    out.update(_pose_arrays(motion.camera, f"{prefix}/camera"))
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


def _pose_arrays(pose: Any, prefix: str) -> dict[str, np.ndarray]:
    """One pose's arrays under `prefix/`: translation, rotation, scale, and `stretch` where
    the pose has off-diagonal stretch terms."""
    out = {f"{prefix}/{fld}": arr for fld, arr in zip(_POSE_FIELDS, pose)}
    off = pose[3] if len(pose) > 3 else None
    if off is not None:
        out[f"{prefix}/{_STRETCH_FIELD}"] = off
    return out


def _stack_rows(rows: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per-frame arrays stacked over frames; a frame without a pose's `stretch` (diagonal
    there) gets zeros of its `scale`'s shape."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    out = {}
    for key in keys:
        fill = key[: -len(_STRETCH_FIELD)] + "scale" if key.endswith("/" + _STRETCH_FIELD) else None
        out[key] = np.stack([r[key] if key in r else np.zeros_like(r[fill]) for r in rows])  # type: ignore[index]
    return out


def _meta(baked: BakedMotion) -> dict[str, Any]:
    """The header of a bake file."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "scene": baked.scene,
        "fps": baked.fps,
        "shutter": {"angle": baked.shutter_angle, "position": baked.shutter_position},
        "samples_per_frame": baked.samples_per_frame,
    }


def write_baked(baked: BakedMotion, path: str | Path) -> Path:
    """Write `.json` or `.npz` (by extension) atomically; returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".json", ".npz"):
        raise BakeFileError(f"{path}: unknown extension {path.suffix!r} (use .json or .npz)")
    if not path.parent.exists():
        raise BakeFileError(f"{path}: directory {path.parent} does not exist")
    with writing(path, "writing the baked motion", suffix=suffix) as tmp:
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
                        "samples": _nest(_motion_arrays(f.across_shutter, "m", False)),
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
            per_frame = [_motion_arrays(f.across_shutter, "samples", True) for f in baked.frames]
            at_frame = [_motion_arrays(f.at_frame, "at_frame", True) for f in baked.frames]
            for rows in (per_frame, at_frame):
                for key, stacked in _stack_rows(rows).items():
                    # at_frame values drop their time axis of 1 (particle ids have none)
                    arrays[key] = stacked[:, 0] if key.startswith("at_frame/") and not key.endswith("/ids") else stacked
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
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
MAX_BAKE_FRAMES = MAX_FRAMES  # frames in one baked-motion file (as in one timeline)
MAX_BAKE_ARRAY_BYTES = 4 * 1024**3  # its arrays once decompressed (NPZ)


def read_document(path: str | Path) -> dict[str, Any]:
    """A baked file as plain data, its layout checked no further than format and version:
    the meta fields plus `frames`, and for NPZ every array by its key under `arrays`
    (docs/bake-format.md). `read_baked` builds the typed records from it. Raises
    BakeFileError on a bad file.

    Bounded like a scene: a regular file of at most MAX_BAKE_BYTES, JSON nesting and
    numbers as Python's json module allows (a RecursionError is a bad file), NPZ arrays
    declared no larger than MAX_BAKE_ARRAY_BYTES in all before any is decompressed, and
    no pickled objects."""
    from ..limits import open_bounded

    path = Path(path)
    fh = open_bounded(path, MAX_BAKE_BYTES, "baked-motion file", BakeFileError)
    try:
        with fh:
            head = fh.read(6)
            fh.seek(0)
            if not head:
                raise BakeFileError(f"{path}: the baked-motion file is empty")
            if path.suffix.lower() == ".json" or head[:1] in (b"{", b"[", b" ", b"\n"):
                doc = json.loads(fh.read().decode("utf-8"), parse_constant=_no_constant, parse_int=_bounded_int)
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
            if dtype.kind not in "fiubU":
                raise BakeFileError(f"{path}: array {info.filename!r} holds {dtype} values; a bake holds real numbers")
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


_MALFORMED = (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError)
MAX_INT_DIGITS = 20  # an integer in a bake file (a frame number is at most 10^9)
MAX_SAMPLES_PER_FRAME = 256  # as render.shutter_samples


def _no_constant(name: str) -> float:
    """JSON's NaN / Infinity / -Infinity, refused where the file is parsed (Python's json
    accepts them; no bake value may be one)."""
    raise ValueError(f"{name} is not a finite number")


def _bounded_int(text: str) -> int:
    """A JSON integer literal of at most MAX_INT_DIGITS digits (a frame number of 4,000
    digits is a malformed record, not a number to carry into error messages)."""
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {len(text.lstrip('-'))} digits (at most {MAX_INT_DIGITS})")
    return int(text)


def _whole(value: Any, what: str, low: int, high: int) -> int:
    """A whole number from a record (a JSON int, an integral finite float, a numpy
    integer) within [low, high]; a bool, text, complex, fractional or non-finite value is
    a ValueError naming `what`."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} is {type(value).__name__} {str(value)[:24]!r}, expected a whole number")
    if not (np.isfinite(value) and float(value).is_integer()):
        raise ValueError(f"{what} is {float(value):g}, expected a whole number")
    if not low <= value <= high:
        raise ValueError(f"{what} is {float(value):g}, expected {low} to {high}")
    return int(value)


def _real(value: Any, what: str) -> float:
    """A finite real number from a record (no bool, text or complex value)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) or not np.isfinite(value):
        raise ValueError(f"{what} is {str(value)[:24]!r}, expected a finite number")
    return float(value)


def _numbers(value: Any, what: str, dtype: Any = np.float64) -> np.ndarray:
    """An array of real numbers (or booleans for `dtype=bool`): text, complex or object
    values are a ValueError naming `what` (np.asarray(..., float) would parse '1' and drop
    an imaginary part with only a warning)."""
    a = np.asarray(value)
    if a.dtype.kind not in ("b" if dtype is bool else "fiu"):
        raise ValueError(f"{what} holds {a.dtype} values, expected {'booleans' if dtype is bool else 'real numbers'}")
    return a.astype(dtype)


def read_baked(path: str | Path, half: bool = False, frames: Collection[int] | None = None) -> BakedMotion:
    """The one reader of bake files (.json or .npz): the typed `BakedMotion`, every frame
    checked (finite times, poses finite with unit rotations, shapes matching the header's
    samples_per_frame). Raises BakeFileError naming the file (and the frame) on a bad one.

    JSON carries no vertices or particles; NPZ carries them at the frame time and across
    the shutter (docs/bake-format.md). `half`: the frames it feeds are half-float, so a
    light's radiance seen directly must be one a half holds (limits.py). `frames`: build
    and check only these frame numbers (a job's selection), so a long file within its byte
    budget never costs a record per frame the job does not use (docs/bake-format.md). A
    file of more than MAX_BAKE_FRAMES frames is refused before any is built."""
    path = Path(path)
    doc = read_document(path)
    try:
        shutter = doc["shutter"]
        header = (str(doc["scene"]), str(doc["fps"]), _real(shutter["angle"], "shutter.angle"), str(shutter["position"]),
                  _whole(doc["samples_per_frame"], "samples_per_frame", 1, MAX_SAMPLES_PER_FRAME))
    except _MALFORMED as exc:
        raise BakeFileError(f"{path}: its header (scene, fps, shutter, samples_per_frame) is malformed: {type(exc).__name__}: {exc}") from None
    scene, fps, angle, position, samples = header
    try:
        listed = doc["arrays"]["frames"] if "arrays" in doc else doc["frames"]
        if len(listed) > MAX_BAKE_FRAMES:
            raise BakeFileError(f"{path}: {len(listed)} frames; the limit is {MAX_BAKE_FRAMES} (bake fewer frames per file)")
        numbers = [_whole(r if "arrays" in doc else r["frame"], f"frames[{k}].frame", -MAX_FRAME_NUMBER, MAX_FRAME_NUMBER) for k, r in enumerate(listed)]
        chosen = None if frames is None else set(frames)
        wanted = [k for k, n in enumerate(numbers) if chosen is None or n in chosen]
        records = _npz_records(doc["arrays"], wanted) if "arrays" in doc else [listed[k] for k in wanted]
    except _MALFORMED as exc:
        raise BakeFileError(f"{path}: the frame list is malformed ({type(exc).__name__}: {exc})") from None
    baked_frames = []
    for number, rec in zip([numbers[k] for k in wanted], records):
        try:
            frame = _frame(rec, number)
        except _MALFORMED as exc:
            raise BakeFileError(f"{path}: frame {number} is malformed ({type(exc).__name__}: {exc})") from None
        _check_frame(frame, samples, path, half)
        baked_frames.append(frame)
    return BakedMotion(scene, fps, angle, position, baked_frames)


def _frame(rec: dict[str, Any], number: int) -> BakedFrame:
    """One frame's record (the JSON layout, or NPZ arrays nested the same way)."""
    time = _real(rec["time"], "time")
    if len(rec["shutter"]) != 2:
        raise ValueError(f"shutter has {len(rec['shutter'])} values, expected [open, close]")
    shutter = (_real(rec["shutter"][0], "shutter[0]"), _real(rec["shutter"][1], "shutter[1]"))
    across = rec["samples"]
    count = np.asarray(across["camera"]["translation"]).shape[0]
    sample_times = _numbers(rec.get("sample_times", []), "sample_times").reshape(-1)
    if sample_times.size != count:  # no sample times in the file: the shutter's, evenly spaced
        sample_times = np.linspace(shutter[0], shutter[1], count)
    return BakedFrame(
        frame=number,
        time=time,
        shutter=shutter,
        sample_times=sample_times,
        at_frame=_scene_motion(rec["at_frame"], np.array([time]), single=True),
        across_shutter=_scene_motion(across, sample_times, single=False),
    )


def _scene_motion(node: dict[str, Any], times: np.ndarray, single: bool) -> "SceneMotion":
    """A SceneMotion from its nested layout; `single`: the values have no time axis (the
    `at_frame` record), one is added."""
    from ..dynamics.particles import ParticleSamples
    from ..motion import Pose, SceneMotion
    from ..motion.pose import offdiag_or_none

    def arr(value: Any, dtype: Any = np.float64) -> np.ndarray:
        a = _numbers(value, "a value", dtype)
        return a[None] if single else a

    def pose(d: dict[str, Any]) -> Pose:
        off = d.get(_STRETCH_FIELD)  # absent in files written before stretches, and where diagonal
        return Pose(arr(d["translation"]), arr(d["rotation"]), arr(d["scale"]), offdiag_or_none(None if off is None else arr(off)))

    return SceneMotion(
        times=times,
        objects={n: pose(d) for n, d in node.get("objects", {}).items()},
        camera=pose(node["camera"]),
        camera_scalars={c: arr(v) for c, v in node["camera_scalars"].items()},
        lights={n: pose(d) for n, d in node.get("lights", {}).items()},
        light_scalars={n: {c: arr(v) for c, v in d.items()} for n, d in node.get("light_scalars", {}).items()},
        vertices={n: arr(v) for n, v in node.get("vertices", {}).items()},
        particles={n: ParticleSamples(ids=_numbers(d["ids"], f"particle ids of {n!r}", np.int64), positions=arr(d["positions"]), alive=arr(d["alive"], bool)) for n, d in node.get("particles", {}).items()},
    )


def _check_frame(frame: BakedFrame, samples: int, path: Path, half: bool = False) -> None:
    """A frame read back: finite times, the header's sample count, every value finite and
    every rotation a unit quaternion; the error names the frame, the owner, the channel
    and the time."""
    if not (np.isfinite(frame.time) and np.isfinite(frame.shutter).all() and np.isfinite(frame.sample_times).all()):
        raise BakeFileError(f"{path}: frame {frame.frame}: its time, shutter or sample times are not finite")
    if frame.samples != samples:
        raise BakeFileError(f"{path}: frame {frame.frame}: {frame.samples} shutter samples, the header says {samples} (samples_per_frame)")
    for motion in (frame.at_frame, frame.across_shutter):
        problems = motion_problems(motion, half)
        if problems:
            raise BakeFileError(f"{path}: frame {frame.frame}: {problems[0][2]}")
    # the frame-time geometry must match the shutter samples' (the renderer stacks them)
    at, across = frame.at_frame, frame.across_shutter
    shapes = [(f"vertices of {n!r}", v.shape[1:], across.vertices[n].shape[1:] if n in across.vertices else None) for n, v in at.vertices.items()]
    shapes += [(f"particles of {n!r}", (ps.positions.shape[1:], ps.alive.shape[1:], ps.ids.shape),
                (across.particles[n].positions.shape[1:], across.particles[n].alive.shape[1:], across.particles[n].ids.shape) if n in across.particles else None)
               for n, ps in at.particles.items()]
    for what, at_shape, across_shape in shapes:
        if at_shape != across_shape:
            raise BakeFileError(f"{path}: frame {frame.frame}: the {what} at the frame time have shape {at_shape}, across the shutter {across_shape}")


def _npz_records(arrays: dict[str, np.ndarray], indices: list[int]) -> list[dict[str, Any]]:
    """The NPZ layout (stacked over frames) as the JSON layout, one record per frame at
    `indices`; vertices and particles nest like the rest."""
    out = []
    for k in indices:
        f = arrays["frames"][k]
        rec: dict[str, Any] = {"frame": f, "time": arrays["times"][k], "shutter": arrays["shutter"][k], "at_frame": {}, "samples": {}}
        if "sample_times" in arrays:
            rec["sample_times"] = arrays["sample_times"][k]
        for key, arr in arrays.items():
            head, _, rest = key.partition("/")
            if head not in ("at_frame", "samples") or not rest:
                continue
            parts = rest.split("/")
            node = rec[head]
            for p in parts[:-1]:
                node = node.setdefault(p, {})
            node[parts[-1]] = arr[k]
        out.append(rec)
    return out
