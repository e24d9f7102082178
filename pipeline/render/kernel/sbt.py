"""One shader-binding-table owner for the scenes one kernel traces (docs/rendering.md).

The motion_path kernel traces the static scene, the broadphase and the atlas of
everything that moves in one megakernel. On LLVM (Embree) each query takes its scene as
an argument, so any number of scenes works. On CUDA (OptiX) the first trace compiled into
a kernel fixes the kernel's pipeline and shader binding table (SBT); drjit disables every
later trace against another SBT ("more than one OptiX shader binding table ... Disabling
this ray tracing operation") and it reads as a miss: movers vanish, frames "succeed".

Mitsuba 3.9 shares one pipeline and SBT among scenes: a scene built with another
`mi.Scene` among its properties appends its hit records to that scene's SBT and traces
with it (src/render/scene_optix.inl, `other_scene`). The pipeline is the owner's, made
for the owner's shape types: a scene with a type the owner lacks fails to build on the
GPU ("OptixProgramGroupMapping: shape type not mapped!"). So each job has one owner, a
never-traced root scene holding one tiny stand-in of each shape type its traced scenes
use, and every traced scene is built against it (`SbtOwner.scene`).

Every variant builds its traced scenes through the owner, which checks and records them;
only CUDA variants pass the root scene itself (`share`). Mitsuba's scene skips a nested
scene on LLVM too (src/render/scene.cpp), but Embree then commits the BVH as a nested
scene's, from the calling thread alone instead of drjit's whole pool
(scene_embree.inl, `is_nested_scene`): the CPU path keeps its BVH builds, and its bits.

`check_shared` is the invariant, checked before every render on every variant (the CPU
catches what only the GPU would show): scenes traced together share one owner, and the
owner's shape types cover each one's.
"""

from __future__ import annotations

from typing import Any, Iterable, Mapping, Sequence

SBT_KEY = "sbt_owner"  # the property under which a traced scene names its owner

# Mitsuba's ShapeType of each shape plugin our scene dictionaries use (every triangle mesh
# is one type: a rectangle is a mesh to OptiX, scene_optix.inl's init_optix_config)
PLUGIN_TYPES: dict[str, str] = {
    "sphere": "Sphere",
    "disk": "Disk",
    "cylinder": "Cylinder",
    "ellipsoids": "Ellipsoids",
    **{plugin: "Mesh" for plugin in ("cube", "rectangle", "obj", "ply", "serialized")},
}

def _ellipsoid_stand_in() -> dict[str, Any]:
    """One tiny ellipsoid (the broadphase's shape type: render/kernel/broadphase.py)."""
    import mitsuba as mi
    import numpy as np

    tensor = lambda a: mi.TensorXf(np.asarray(a, dtype=np.float32))  # noqa: E731
    return {"type": "ellipsoids", "extent": 1.0, "centers": tensor([[0.0, 0.0, 0.0]]), "scales": tensor([[1e-3] * 3]), "quaternions": tensor([[0.0, 0.0, 0.0, 1.0]])}


# one tiny stand-in per ShapeType: never traced, only its program group matters (a
# callable where the record needs the variant's types)
STAND_INS: dict[str, Any] = {
    "Mesh": {"type": "cube"},
    "Sphere": {"type": "sphere", "radius": 1e-3},
    "Disk": {"type": "disk"},
    "Cylinder": {"type": "cylinder", "radius": 1e-3},
    "Ellipsoids": _ellipsoid_stand_in,
}


class SbtOwnerError(RuntimeError):
    """Scenes traced in one kernel do not share one SBT owner that covers their shape
    types: on CUDA some of their traces would be disabled (a bug, never bad input)."""


def _type_bits(names: Iterable[str]) -> int:
    import mitsuba as mi

    bits = 0
    for name in names:
        bits |= int(getattr(mi.ShapeType, name))
    return bits


def optix_key(bits: int) -> int:
    """A scene's `shape_types()` as OptiX's pipeline sees it: a rectangle is a mesh, as
    in Mitsuba's `init_optix_config`."""
    import mitsuba as mi

    rect, mesh = int(mi.ShapeType.Rectangle), int(mi.ShapeType.Mesh)
    if bits & rect == rect:
        bits = (bits & ~rect) | mesh
    return bits


def type_names(bits: int) -> list[str]:
    """The ShapeType names of `bits` (after `optix_key`), for messages."""
    import mitsuba as mi

    names = [name for name, value in mi.ShapeType.__members__.items() if int(value) and name not in ("Rectangle", "EllipsoidsMesh") and bits & int(value) == int(value)]
    return names or [f"0x{bits:x}"]


def dict_types(d: Mapping[str, Any]) -> set[str]:
    """The ShapeType names of the shapes of a scene dictionary: plugin dictionaries by
    `PLUGIN_TYPES`, shapes already built by their own `shape_type()`. An unknown shape
    plugin is not named here; `check_shared` then names it after the build."""
    import mitsuba as mi

    out: set[str] = set()
    for value in d.values():
        if isinstance(value, Mapping) and value.get("type") in PLUGIN_TYPES:
            out.add(PLUGIN_TYPES[str(value["type"])])
        elif isinstance(value, mi.Shape):
            out.update(type_names(optix_key(int(value.shape_type()))))
    return out


def shares_sbt() -> bool:
    """Whether the active variant traces with OptiX, whose kernels need one shared SBT."""
    import mitsuba as mi

    return str(mi.variant()).startswith("cuda")


class SbtOwner:
    """The never-traced root scene whose pipeline and SBT every traced scene of one job
    shares, with one stand-in of each shape type in `types` (ShapeType names). `share`:
    pass the root to each scene (default: on CUDA variants, `shares_sbt`)."""

    def __init__(self, types: Iterable[str], share: bool | None = None) -> None:
        from ...variant import load_dict

        self.types = sorted(set(types) or {"Mesh"})
        unknown = [t for t in self.types if t not in STAND_INS]
        if unknown:
            raise SbtOwnerError(f"no SBT stand-in for shape types {unknown} (known: {sorted(STAND_INS)})")
        self.share = shares_sbt() if share is None else bool(share)
        self.root = load_dict({"type": "scene", **{f"stand_in_{t.lower()}": STAND_INS[t]() if callable(STAND_INS[t]) else dict(STAND_INS[t]) for t in self.types}}) if self.share else None
        self.bits = _type_bits(self.types)
        self._members: dict[int, Any] = {}  # id -> scene, held so that ids stay unique

    def scene(self, d: Mapping[str, Any]) -> Any:
        """`d` (a scene dictionary) built against this owner: with `share` it traces with
        the owner's pipeline and SBT (CUDA); without, it is built as it is (LLVM)."""
        from ...variant import load_dict

        missing = dict_types(d) - set(self.types)
        if missing:  # on CUDA the build itself would fail: "shape type not mapped"
            raise SbtOwnerError(f"a traced scene has shape types {sorted(missing)} that its SBT owner lacks ({self.types})")
        scene = load_dict({**d, SBT_KEY: self.root} if self.share else dict(d))
        self._members[id(scene)] = scene
        return scene

    def owns(self, scene: Any) -> bool:
        """Whether `scene` was built by `scene()` and not forgotten since."""
        return self._members.get(id(scene)) is scene

    def forget(self, scenes: Iterable[Any]) -> None:
        """Scenes no longer traced (a particle group that grew): their references go."""
        for s in scenes:
            if self.owns(s):
                del self._members[id(s)]


def check_shared(scenes: Sequence[Any], owner: SbtOwner | None) -> None:
    """Raise SbtOwnerError unless `scenes`, traced in one kernel, are one scene or all
    built by `owner`, and the owner's shape types cover each one's."""
    if len(scenes) <= 1:
        return
    if owner is None:
        raise SbtOwnerError(f"{len(scenes)} scenes are traced in one kernel without a shared SBT owner: on CUDA all but the first would read as misses")
    for k, s in enumerate(scenes):
        if not owner.owns(s):
            raise SbtOwnerError(f"traced scene {k} of {len(scenes)} was not built by the kernel's SBT owner: on CUDA its rays would read as misses")
        uncovered = optix_key(int(s.shape_types())) & ~owner.bits
        if uncovered:
            raise SbtOwnerError(f"traced scene {k} has shape types {type_names(uncovered)} that its SBT owner lacks ({owner.types}): on CUDA it would not build")
