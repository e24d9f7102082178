"""A thing's local pose: parent_from_thing at any times, from its `transform:` block (the
base) and its motion block (static, keyframes, procedural). The same rules serve objects,
the camera, lights, skeleton bones and blend-shape weights (motion/deform.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from ..errors import ExpressionValueError, SceneError, TrackError
from ..scene.motion_schema import KeyframeMotion, ProceduralMotion
from .keyframes import RotationTrack, VectorTrack
from .procedural import apply_layers, procedural_layers, procedural_scalars
from .rotation import transform_quat

if TYPE_CHECKING:
    from ..scene.loader import LoadedScene
    from ..scene.source import Loc


def broadcast(value: np.ndarray, count: int) -> np.ndarray:
    """A value of shape [..., D] repeated as [count, D] (a copy, writable)."""
    return np.broadcast_to(value, (count, value.shape[-1])).copy()


def vec3(scale: float | tuple[float, float, float]) -> np.ndarray:
    """A number or a triple as a 3-vector (a uniform scale, a grey colour)."""
    return np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)).copy()


@dataclass
class LocalPose:
    """parent_from_thing at T times, and the thing's animated scalars (fov, intensity ...)."""

    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    scalars: dict[str, np.ndarray]


def local_pose(
    loaded: "LoadedScene",
    loc: "Loc",
    motion: Any,
    base: tuple[np.ndarray, np.ndarray, np.ndarray],
    t: np.ndarray,
    scalar_dims: Mapping[str, int],
) -> LocalPose:
    """parent_from_thing at times t from its base transform and motion block (static,
    keyframes, procedural); `scalar_dims` names the scalar channels the thing may key and
    their width (1 or 3). A bad key or expression value is a SceneError located at `loc`."""
    count = len(t)
    translation, rotation, scale = (broadcast(b, count) for b in base)
    scalars: dict[str, np.ndarray] = {}
    mloc = (*loc, "motion")
    try:
        if isinstance(motion, KeyframeMotion):
            seconds = 1.0 if motion.time_unit == "seconds" else float(1 / loaded.scene.timeline.rate)
            for name, channel in motion.channels.items():
                cloc = (*mloc, "channels", name)
                try:
                    if name == "rotate":
                        rotation = RotationTrack.compile(channel, motion.interpolation, motion.extrapolation, seconds)(t)
                    elif name == "translate":
                        translation = VectorTrack.compile(channel, motion.interpolation, motion.extrapolation, seconds, 3)(t)
                    elif name == "scale" and "scale" not in scalar_dims:
                        scale = _vector_or_uniform(channel, motion, seconds, t)
                    else:
                        dim = scalar_dims.get(name, 1)
                        if dim == 3:
                            scalars[name] = _vector_or_uniform(channel, motion, seconds, t)
                        else:
                            scalars[name] = VectorTrack.compile(channel, motion.interpolation, motion.extrapolation, seconds, 1)(t)[:, 0]
                except TrackError as exc:
                    raise SceneError([loaded.source.problem((*cloc, *exc.loc), str(exc))]) from None
        elif isinstance(motion, ProceduralMotion):
            translation, rotation, scale = apply_layers(translation, rotation, scale, procedural_layers(motion, t))
            for name, values in procedural_scalars(motion, t).items():
                scalars[name] = values[:, None].repeat(3, axis=1) if scalar_dims.get(name, 1) == 3 else values
    except ExpressionValueError as exc:
        raise SceneError([loaded.source.problem((*mloc, *exc.loc), str(exc))]) from None
    return LocalPose(translation, rotation, scale, scalars)


def _vector_or_uniform(channel: Any, motion: KeyframeMotion, seconds: float, t: np.ndarray) -> np.ndarray:
    """A channel keyed with either one number (uniform) or three per key -> [T, 3]."""
    uniform = all(not isinstance(k.value, tuple) for k in channel.keys)
    dim = 1 if uniform else 3
    values = VectorTrack.compile(channel, motion.interpolation, motion.extrapolation, seconds, dim)(t)
    return np.repeat(values, 3, axis=1) if uniform else values


def object_base(obj: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translation [3], rotation [4] wxyz, scale [3]) of a thing's `transform:` block."""
    return transform_base(obj.transform)


def transform_base(tr: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translation [3], rotation [4] wxyz, scale [3]) of a `transform:` block."""
    return np.asarray(tr.translate, dtype=np.float64), transform_quat(tr.rotate), vec3(tr.scale)
