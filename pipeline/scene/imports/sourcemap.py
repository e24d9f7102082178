"""A source map that also locates problems in records expanded from imports."""

from __future__ import annotations

from dataclasses import dataclass, field

from ...errors import Problem
from ..source import Loc, SourceMap, yaml_path
from .expansion import Origin


@dataclass(frozen=True)
class ImportedSourceMap(SourceMap):
    """Problems in an imported record point at the asset file and node (prim), or at the
    scene-file key that set the value (an override, the import's root transform)."""

    origins: dict[tuple[str, int], Origin] = field(default_factory=dict)
    camera_origin: Origin | None = None

    def problem(self, loc: Loc, message: str, key: bool = False) -> Problem:
        """A problem at `loc`: in the asset file and node when the record was imported, at the
        scene-file key when that key set the value."""
        origin, rest = None, ()
        if len(loc) >= 2 and (loc[0], loc[1]) in self.origins:
            origin, rest = self.origins[(loc[0], loc[1])], tuple(loc[2:])
        elif loc and loc[0] == "camera" and self.camera_origin is not None:
            origin, rest = self.camera_origin, tuple(loc[1:])
        if origin is None:
            return super().problem(loc, message, key=key)
        if rest and rest[0] in origin.yaml_keys:
            return super().problem((*origin.yaml_keys[rest[0]], *rest[1:]), message, key=key)
        if origin.default is not None:
            return super().problem(origin.default, message, key=key)
        where = origin.where + (f" {yaml_path(rest)}" if rest else "")
        return Problem(origin.file, None, None, where, message)
