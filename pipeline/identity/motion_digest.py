"""One digest of baked frames (the motion hash `--resume` compares), walking every field
of the records generically: a field added to `BakedFrame` or `SceneMotion` is covered
without touching this file.

A frame's key does not depend on what things are called (docs/reruns.md): with an
`Order` (the scene's objects and lights in scene order) the dicts keyed by an object's or
a light's name are walked under its place in the scene instead (`o3`, `l0`), so renaming
an object keeps every frame, and `frame_digests` gives one digest per thing that moves,
so a rerun can say whose motion changed for which frames.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import TYPE_CHECKING, Any, Iterator, Mapping, Sequence

from ..bake.records import BakedFrame

if TYPE_CHECKING:  # numpy is imported where a frame's motion is walked, not where a kept identity is read
    import numpy as np

# SceneMotion's fields keyed by a name: an object's ("o") or a light's ("l")
ENTITY_FIELDS = {"objects": "o", "vertices": "o", "particles": "o", "lights": "l", "light_scalars": "l"}
# the parts of a frame that are neither an object nor a light (its times, the camera's own)
CAMERA_FIELDS = ("camera", "camera_scalars")


@dataclasses.dataclass(frozen=True)
class Order:
    """The scene's object names and light names (`light<i>` when unnamed) in scene order:
    what turns a name into its place (`o3`, `l0`) in a frame's key."""

    objects: tuple[str, ...] = ()
    lights: tuple[str, ...] = ()

    @classmethod
    def of(cls, scene: Any) -> "Order":
        """The order of a validated scene's objects and lights."""
        from ..scene.lights import light_key

        return cls(tuple(o.name for o in scene.objects), tuple(light_key(light, i) for i, light in enumerate(scene.lights)))

    def labels(self) -> dict[str, dict[str, str]]:
        """For each name-keyed SceneMotion field, name -> label."""
        by_kind = {"o": {n: f"o{i}" for i, n in enumerate(self.objects)}, "l": {n: f"l{i}" for i, n in enumerate(self.lights)}}
        return {field: by_kind[kind] for field, kind in ENTITY_FIELDS.items()}

    def name_of(self, label: str) -> str | None:
        """The name of a label's object or light in this order, or None."""
        kind, index = label[:1], label[1:]
        names = {"o": self.objects, "l": self.lights}.get(kind)
        if names is None or not index.isdigit() or int(index) >= len(names):
            return None
        return names[int(index)]


def leaves(value: Any, key: str = "", labels: Mapping[str, Mapping[str, str]] | None = None) -> Iterator[tuple[str, np.ndarray]]:
    """Every number of `value` as (path, float64 array): dataclasses field by field, named
    tuples by name, dicts in sorted key order, sequences of records by index; numbers,
    tuples of numbers and arrays are leaves; None is skipped. `labels`: field name ->
    {name: label}: a dict held in a field of that name is walked under the labels of its
    keys (a key without a label keeps its name)."""
    import numpy as np

    if value is None:
        return
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from _field(getattr(value, f.name), key, f.name, labels)
    elif isinstance(value, tuple) and hasattr(value, "_fields"):
        for name in value._fields:
            yield from _field(getattr(value, name), key, name, labels)
    elif isinstance(value, dict):
        for k in sorted(value):
            yield from leaves(value[k], f"{key}/{k}", labels)
    elif isinstance(value, (list, tuple)) and value and not isinstance(value[0], (int, float, np.number)):
        for i, v in enumerate(value):
            yield from leaves(v, f"{key}/{i}", labels)
    else:
        yield key, np.ascontiguousarray(value, dtype=np.float64)


def _field(value: Any, key: str, name: str, labels: Mapping[str, Mapping[str, str]] | None) -> Iterator[tuple[str, np.ndarray]]:
    """The leaves of one field; a name-keyed dict walked under its labels."""
    rename = labels.get(name) if labels else None
    if rename is not None and isinstance(value, dict):
        relabelled = {rename.get(k, k): v for k, v in value.items()}
        if len(relabelled) == len(value):  # a label equal to another key's name: keep the names
            value = relabelled
    yield from leaves(value, f"{key}/{name}", labels)


def _digest(h: Any, key: str, arr: np.ndarray) -> None:
    """Feed one leaf (path, shape, float64 bytes) to a hash."""
    h.update(key.encode())
    h.update(repr(arr.shape).encode())
    h.update(arr.tobytes())


def fingerprint(frames: Sequence[BakedFrame], order: Order | None = None) -> str:
    """A stable SHA-256 digest (hex) of the frames: every leaf's path, shape and float64
    bytes, so any change to anything that animates (objects, camera and its scalars,
    lights and their scalars, vertices, particles, times) changes it. With `order`,
    objects and lights count by their place in the scene, not their names."""
    labels = order.labels() if order is not None else None
    h = hashlib.sha256()
    for frame in frames:
        for key, arr in leaves(frame, labels=labels):
            _digest(h, key, arr)
    return h.hexdigest()


def part_of(key: str) -> str:
    """Which thing a leaf's path belongs to: an object's or light's label (`o3`, `l0`),
    `camera`, or `timing` (the frame's times and shutter)."""
    parts = key.strip("/").split("/")
    if parts and parts[0] in ("at_frame", "across_shutter"):
        parts = parts[1:]
    if len(parts) >= 2 and parts[0] in ENTITY_FIELDS:
        return parts[1]
    if parts and parts[0] in CAMERA_FIELDS:
        return "camera"
    return "timing"


def frame_digests(frame: BakedFrame, order: Order | None = None) -> tuple[str, dict[str, str]]:
    """(the frame's fingerprint, {part: digest}) in one walk: the parts are each moving
    thing's own digest (`part_of`), 16 hex digits each, so two frames' keys can say whose
    motion differs."""
    labels = order.labels() if order is not None else None
    whole = hashlib.sha256()
    parts: dict[str, Any] = {}
    for key, arr in leaves(frame, labels=labels):
        _digest(whole, key, arr)
        part = part_of(key)
        if part not in parts:
            parts[part] = hashlib.sha256()
        _digest(parts[part], key, arr)
    return whole.hexdigest(), {p: h.hexdigest()[:16] for p, h in sorted(parts.items())}
