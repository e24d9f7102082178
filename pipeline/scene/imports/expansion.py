"""What an import reader produces (`Expansion`, each record with its `Origin`) and the two
errors it raises: `ImportFileError` (the asset file) and `SpecError` (the import entry)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ...errors import MotionError, Problem, SceneError

if TYPE_CHECKING:
    from ..source import Loc


class ImportFileError(SceneError):
    """An imported asset file is unreadable, malformed or uses what we do not support;
    names the file and the node / mesh / accessor (glTF) or prim (USD)."""

    def __init__(self, file: str, where: str, message: str) -> None:
        super().__init__([Problem(file, None, None, where, message)])


class SpecError(MotionError):
    """A problem with the scene file's import entry itself: its `field` names what. The
    reader raises it; `expand_imports` turns it into a problem located at that field."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class Origin:
    """Where an expanded record came from: the asset `file` and `where` in it, and the
    keys that came from the scene file instead (key -> its YAML location)."""

    file: str
    where: str
    yaml_keys: dict[str, "Loc"] = field(default_factory=dict)
    default: "Loc | None" = None  # a record made by the scene file itself (an import's root)


@dataclass
class Expansion:
    """What one reader produced: records as YAML-like dicts, each with its origin."""

    objects: list[tuple[dict[str, Any], Origin]] = field(default_factory=list)
    materials: list[tuple[dict[str, Any], Origin]] = field(default_factory=list)
    lights: list[tuple[dict[str, Any], Origin]] = field(default_factory=list)
    cameras: list[tuple[str, dict[str, Any], Origin]] = field(default_factory=list)  # (node name, record, origin)


def import_frames(take: Any, spec: Any, index: int, shown: str, default_root: str, file_units: float = 1.0, file_up: str = "y") -> tuple[list[tuple[dict[str, Any], Origin]], str]:
    """The import's root empty (carrying the entry's `transform`) and, when the file's
    units or up axis differ from ours (metres, +Y up), a `<root>.stage` empty under it that
    scales by metres-per-unit and turns +Z up to +Y up (-90 degrees about X); the entry's
    `units:` / `up_axis:` override the file's. Returns the records and the name the file's
    own top-level nodes take as parent. `take` makes a name unique (the reader's)."""
    root = take(spec.root or default_root)
    records = [({"name": root, "shape": "empty", "transform": spec.transform.model_dump(mode="json", exclude_defaults=True)},
                Origin(shown, "<root>", {"transform": ("imports", index, "transform")}, ("imports", index)))]
    units = float(spec.units if spec.units is not None else file_units)
    up = spec.up_axis or file_up
    if units == 1.0 and up == "y":
        return records, root
    transform: dict[str, Any] = {"scale": [units] * 3}
    if up == "z":
        transform["rotate"] = {"euler": [-90.0, 0.0, 0.0]}
    stage = take(f"{root}.stage")
    keys = {k: ("imports", index, k) for k in ("units", "up_axis") if getattr(spec, k) is not None}
    records.append(({"name": stage, "shape": "empty", "parent": root, "transform": transform}, Origin(shown, "<stage units and up axis>", keys, ("imports", index))))
    return records, stage
