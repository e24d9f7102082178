"""Load a scene: YAML (safely, with source positions) -> validated, immutable `Scene`.

Every problem becomes one `Problem(file, line, column, yaml_path, message)`; all of them
are collected and raised together as one `SceneError`, before any long job starts. The
YAML reading and source positions are `source.py`, pydantic errors -> problems
`problems.py`, imports `imports/`, the checks a schema cannot express `checks.py`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from pydantic import ValidationError

from ..errors import Problem, SceneError
from .checks import semantic_problems
from .imports import expand_imports
from .problems import problems_from_validation
from .schema import Scene
from .source import Loc, SourceMap, parse_yaml, read_yaml_file

__all__ = ["LoadedScene", "Loc", "deep_merge", "load_scene"]  # Loc: for type hints of the motion stage


@dataclass(frozen=True)
class LoadedScene:
    """A validated scene with where it came from (for relative asset paths and errors)."""

    scene: Scene
    path: Path
    source: SourceMap
    data: dict[str, Any]

    @property
    def name(self) -> str:
        """The scene's name, else the file's stem."""
        return self.scene.name or self.path.stem

    @property
    def base_dir(self) -> Path:
        """The folder relative asset paths start from."""
        return self.path.parent

    def asset(self, relative: str) -> Path:
        """The absolute path of an asset named relative to the scene file."""
        return (self.base_dir / relative).resolve()


def load_scene(path: str | Path, overrides: Mapping[str, Any] | None = None, assets: bool = True) -> LoadedScene:
    """Read, validate and cross-check a scene file. Raises SceneError with every problem.

    overrides: nested dict merged over the document before validation (presets, CLI flags).
    assets: open and decode every mesh and image the scene names (the validation stage);
    a worker reloading a scene the main process has already checked passes False.
    """
    path = Path(path)
    file = str(path)
    text = read_yaml_file(path, "scene file")
    data, source = parse_yaml(text, file)
    if data is None:
        raise SceneError([Problem(file, 1, 1, "", "the scene file is empty; expected a mapping with at least 'camera'")])
    if not isinstance(data, dict):
        raise SceneError([source.problem((), f"expected a mapping at the top level, got {type(data).__name__}")])
    if overrides:
        data = deep_merge(data, overrides)
    data, source = expand_imports(data, source, path.parent)
    try:
        scene = Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError(problems_from_validation(exc, data, source, Scene)) from None
    problems = semantic_problems(scene, path.parent, source, assets=assets)
    if problems:
        raise SceneError(problems)
    return LoadedScene(scene=scene, path=path.resolve(), source=source, data=data)


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """Merge `over` into a copy of `base`; nested mappings merge, everything else replaces."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out
