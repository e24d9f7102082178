"""Where the farm's per-frame motion comes from: baked here (`bake()`, once, in the main
process, before any worker starts) or read from a file written by `motion bake`
(`--motion FILE`). Either way the result is a list of small `FrameInput`s.

A frame's input is its pose at the frame time (index 0) followed by the N shutter samples
(indices 1..N), which is `BakedFrame.at_frame` followed by `BakedFrame.motion`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..bake import BakeFileError
from ..errors import UsageError
from ..render.frame_renderer import FrameInput
from ..scene.loader import LoadedScene


def _light_keys(loaded: LoadedScene) -> list[str]:
    return [light.name or f"light{i}" for i, light in enumerate(loaded.scene.lights)]


def simulation_for(loaded: LoadedScene, frames: Sequence[int], on_progress: Any = None) -> Any:
    """Simulate once (before sharding), if the scene has dynamics, over the range bake
    owns (`bake.simulation_range`: the whole timeline, not the selection), so every shard
    and every frame range bakes the same motion for the same frame."""
    from ..bake import simulate_for

    if not frames:
        return None
    return simulate_for(loaded, frames, on_progress=on_progress)


def baked_inputs(loaded: LoadedScene, frames: Sequence[int], simulation: Any = None) -> list[FrameInput]:
    """Bake `frames` here and turn them into FrameInputs (poses, vertices, particles)."""
    from ..bake import bake
    from ..render.inputs import inputs_from_baked

    if not frames:
        return []
    return inputs_from_baked(bake(loaded, frames, simulation))


def _check_meta(doc: dict[str, Any], loaded: LoadedScene, path: Path) -> None:
    scene = loaded.scene
    problems = []
    if doc.get("scene") != loaded.name:
        problems.append(f"baked from scene {doc.get('scene')!r}, rendering {loaded.name!r}")
    if str(doc.get("fps")) != str(scene.timeline.rate):
        problems.append(f"fps {doc.get('fps')} differs from the scene's {scene.timeline.rate}")
    if int(doc.get("samples_per_frame", -1)) != scene.render.shutter_samples:
        problems.append(f"{doc.get('samples_per_frame')} shutter samples per frame, the render needs {scene.render.shutter_samples} (render.shutter_samples)")
    sh = doc.get("shutter", {})
    if float(sh.get("angle", -1)) != float(scene.camera.shutter.angle) or sh.get("position") != scene.camera.shutter.position:
        problems.append(f"shutter {sh} differs from the scene's camera shutter")
    if problems:
        raise UsageError(f"--motion {path}: " + "; ".join(problems))


def file_inputs(loaded: LoadedScene, path: str | Path, frames: Sequence[int]) -> list[FrameInput]:
    """FrameInputs for `frames` from a `motion bake` file (.json or .npz)."""
    from ..bake import read_baked

    path = Path(path)
    nonrigid = [o.name for o in loaded.scene.objects if o.shape == "particles" or getattr(o, "deform", None) is not None]
    if nonrigid:
        # the file formats carry rigid poses; particles and vertices are baked in the render
        raise UsageError(f"--motion {path}: {loaded.name} has particle systems or deforming meshes ({', '.join(nonrigid)}); render without --motion so they are baked here")
    doc = read_baked(path)
    try:
        _check_meta(doc, loaded, path)
    except (TypeError, ValueError, AttributeError) as exc:
        raise BakeFileError(f"--motion {path}: its header (scene, fps, shutter, samples_per_frame) is malformed: {exc}") from None
    keys = set(_light_keys(loaded))
    try:
        if "arrays" in doc:
            by_frame = _npz_frames(doc["arrays"])
        else:
            by_frame = {int(f["frame"]): f for f in doc["frames"]}
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise BakeFileError(f"--motion {path}: the frame list is malformed ({type(exc).__name__}: {exc})") from None
    missing = [f for f in frames if f not in by_frame]
    if missing:
        from .frames import format_frames

        raise UsageError(f"--motion {path}: frames {format_frames(missing)} are not in the baked file (it has {format_frames(sorted(by_frame))})")
    out = []
    for f in frames:
        try:
            fi = _frame_input(by_frame[f], f, keys)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            raise BakeFileError(f"--motion {path}: frame {f} is malformed ({type(exc).__name__}: {exc})") from None
        _check_frame(fi, by_frame[f], path)
        out.append(fi)
    return out


def _frame_input(rec: dict[str, Any], f: int, keys: set[str]) -> FrameInput:
    """One frame's record (JSON layout) as a FrameInput: index 0 the frame time, then the
    shutter samples."""
    at, sm = rec["at_frame"], rec["samples"]

    def cat(one: Any, many: Any) -> np.ndarray:
        one = np.asarray(one, dtype=np.float64)
        return np.concatenate([one[None, ...], np.asarray(many, dtype=np.float64)], axis=0)

    def pose(a: dict[str, Any], s: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (cat(a["translation"], s["translation"]), cat(a["rotation"], s["rotation"]), cat(a["scale"], s["scale"]))

    return FrameInput(
        frame=f,
        time=float(rec["time"]),
        shutter=(float(rec["shutter"][0]), float(rec["shutter"][1])),
        objects={n: pose(at["objects"][n], s) for n, s in sm.get("objects", {}).items()},
        camera=pose(at["camera"], sm["camera"])[:2],
        fov=cat(at["camera_scalars"]["fov"], sm["camera_scalars"]["fov"]),
        ortho_width=cat(at["camera_scalars"]["ortho_width"], sm["camera_scalars"]["ortho_width"]) if "ortho_width" in sm["camera_scalars"] else None,
        lights={n: pose(at["lights"][n], s) for n, s in sm.get("lights", {}).items() if n in keys},
        light_scalars={n: {c: cat(at["light_scalars"][n][c], v) for c, v in ch.items()} for n, ch in sm.get("light_scalars", {}).items()},
    )


def _check_frame(fi: FrameInput, rec: dict[str, Any], path: Path) -> None:
    """Every pose of a loaded frame finite, with unit rotations and the right shapes; the
    error names the frame, the object, the channel and the time."""
    from ..bake import pose_problem, scalar_problem

    samples = np.asarray(rec.get("sample_times", []), dtype=np.float64).reshape(-1)
    n = len(fi.fov) - 1
    if samples.size != n:  # no sample times in the file: the shutter's, evenly spaced
        samples = np.linspace(fi.shutter[0], fi.shutter[1], max(n, 0))
    times = np.concatenate([[fi.time], samples])
    if not (np.isfinite(times).all() and np.isfinite(fi.shutter).all()):
        raise BakeFileError(f"--motion {path}: frame {fi.frame}: its time, shutter or sample times are not finite")
    camera_pose = (fi.camera[0], fi.camera[1], np.ones_like(fi.camera[0]))
    tracks = [("camera", camera_pose)] + [(f"object '{n}'", p) for n, p in fi.objects.items()] + [(f"light '{n}'", p) for n, p in fi.lights.items()]
    for who, p in tracks:
        why = pose_problem(*p, times)
        if why is not None:
            raise BakeFileError(f"--motion {path}: frame {fi.frame}: {who}: {why}")
    scalars = [("camera", "fov", fi.fov)] + ([("camera", "ortho_width", fi.ortho_width)] if fi.ortho_width is not None else [])
    scalars += [(f"light '{n}'", c, v) for n, d in fi.light_scalars.items() for c, v in d.items()]
    for who, name, arr in scalars:
        why = scalar_problem(name, arr, times)
        if why is not None:
            raise BakeFileError(f"--motion {path}: frame {fi.frame}: {who}: {why}")


def _npz_frames(arrays: dict[str, np.ndarray]) -> dict[int, dict[str, Any]]:
    """The NPZ layout (stacked over frames) as the JSON layout, per frame."""
    frames = [int(f) for f in arrays["frames"]]
    out: dict[int, dict[str, Any]] = {}
    for k, f in enumerate(frames):
        rec: dict[str, Any] = {"frame": f, "time": float(arrays["times"][k]), "shutter": arrays["shutter"][k], "at_frame": {}, "samples": {}}
        if "sample_times" in arrays:
            rec["sample_times"] = arrays["sample_times"][k]
        for key, arr in arrays.items():
            head, _, rest = key.partition("/")
            if head not in ("at_frame", "samples") or not rest:
                continue
            parts = rest.split("/")
            if parts[0] in ("vertices", "particles"):
                continue
            node = rec[head]
            for p in parts[:-1]:
                node = node.setdefault(p, {})
            node[parts[-1]] = arr[k]
        out[f] = rec
    return out
