"""Guards on baked motion: every pose finite with a unit rotation, every scalar, vertex
and particle position finite, the right shapes. One walk (`motion_problems`) serves the
bake (a SceneError at the owner's block in the scene file) and the reader of bake files
(a BakeFileError naming the file and the frame)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import SceneError
from ..limits import SEEN_RADIANCE, beyond_float32, beyond_half

if TYPE_CHECKING:
    from ..motion import SceneMotion
    from ..scene.loader import LoadedScene

UNIT_TOLERANCE = 1e-6  # | |q| - 1 | allowed for a rotation quaternion


def pose_problem(translation: Any, rotation: Any, scale: Any, times: Any, stretch_offdiag: Any = None) -> str | None:
    """What is wrong with one pose track ([T, 3], [T, 4], [T, 3] at `times` [T], and the
    stretch's off-diagonal terms [T, 3] where present), or None: a wrong shape, a
    non-finite translation, rotation, scale or stretch, a rotation that is not a unit
    quaternion. The message names the channel and the first time at fault."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    channels = [("translation", translation, 3), ("rotation", rotation, 4), ("scale", scale, 3)]
    if stretch_offdiag is not None:
        channels.append(("stretch", stretch_offdiag, 3))
    for channel, arr, width in channels:
        a = np.asarray(arr)
        if a.dtype.kind not in "fiu" or a.ndim != 2 or a.shape != (times.size, width):
            return f"{channel} has shape {a.shape} ({a.dtype}), expected [{times.size}, {width}] numbers"
        bad = beyond_float32(a).any(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            return f"{channel} is not finite in the renderer's float32 at t = {times[k]:.6g} s ({', '.join(f'{v:g}' for v in a[k])})"
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
    bad = beyond_float32(a.reshape(times.size, -1)).any(axis=1)
    if bad.any():
        return f"{name} is not finite in the renderer's float32 at t = {times[int(np.argmax(bad))]:.6g} s"
    return None


def motion_problems(motion: "SceneMotion", half: bool = False) -> list[tuple[str, str, str]]:
    """Every problem of one SceneMotion as (owner, name, message): owner is "camera",
    "objects", "lights", "deform" (an object's vertices) or "emitter" (its particles);
    the message names the owner, the channel and the first time at fault. `half`: the
    frames are half-float, so a light's radiance seen directly must be one a half holds."""
    times = motion.times
    problems: list[tuple[str, str, str]] = []
    poses = [("camera", "", "camera", motion.camera)]
    poses += [("objects", n, f"object '{n}'", p) for n, p in motion.objects.items()]
    poses += [("lights", n, f"light '{n}'", p) for n, p in motion.lights.items()]
    for owner, name, who, pose in poses:
        why = pose_problem(*pose[:3], times, stretch_offdiag=pose[3] if len(pose) > 3 else None)
        if why is not None:
            problems.append((owner, name, f"{who}: {why}"))
    scalars = [("camera", "", "camera", c, arr) for c, arr in motion.camera_scalars.items()]
    scalars += [("lights", n, f"light '{n}'", c, arr) for n, d in motion.light_scalars.items() for c, arr in d.items()]
    for owner, name, who, channel, arr in scalars:
        why = scalar_problem(channel, arr, times)
        if why is None and half and channel in SEEN_RADIANCE and beyond_half(arr).any():
            rows = np.asarray(arr, dtype=np.float64).reshape(times.size, -1)
            k = int(np.argmax(beyond_half(rows).any(axis=1)))
            why = f"{channel} reaches {float(np.max(np.abs(rows[k]))):g} at t = {times[k]:.6g} s, beyond what a half-float EXR holds: use output.pixel_type: float, or lower it"
        if why is not None:
            problems.append((owner, name, f"{who}: {why}"))
    for name, verts in motion.vertices.items():
        why = scalar_problem("vertices", np.asarray(verts).reshape(len(times), -1), times)
        if why is not None:
            problems.append(("deform", name, f"object '{name}': {why}"))
    for name, ps in motion.particles.items():
        pos = np.asarray(ps.positions)
        if pos.size and beyond_float32(pos).any():
            k = int(np.argmax(beyond_float32(pos.reshape(len(times), -1)).any(axis=1)))
            problems.append(("emitter", name, f"particles '{name}': positions are not finite in the renderer's float32 at t = {times[k]:.6g} s"))
    return problems


def check_motion(loaded: "LoadedScene", motion: "SceneMotion") -> None:
    """Refuse evaluated motion with a non-finite value or a non-unit rotation (an
    overflowing expression or generator would otherwise make an object vanish): SceneError
    at the owner's block, naming the object, the channel and the time."""
    from ..scene.lights import light_key

    scene = loaded.scene
    index = {o.name: i for i, o in enumerate(scene.objects)}
    light_index = {light_key(light, i): i for i, light in enumerate(scene.lights)}
    where = {
        "camera": lambda n: ("camera", "motion"),
        "objects": lambda n: ("objects", index.get(n, 0), "motion"),
        "lights": lambda n: ("lights", light_index.get(n, 0), "motion"),
        "deform": lambda n: ("objects", index.get(n, 0), "deform"),
        "emitter": lambda n: ("objects", index.get(n, 0), "emitter"),
    }
    half = scene.output.pixel_type == "half"
    problems = [loaded.source.problem(where[owner](name), message) for owner, name, message in motion_problems(motion, half)]
    if problems:
        raise SceneError(problems)


def check_budget(loaded: "LoadedScene", frames: int) -> None:
    """Refuse a bake whose particle positions would not fit the budget (checks.py)."""
    from ..scene.checks import bake_budget_problems

    problems = bake_budget_problems(loaded.scene, loaded.source, frames)
    if problems:
        raise SceneError(problems)
