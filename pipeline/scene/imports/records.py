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
