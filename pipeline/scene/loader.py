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
from .checks import numeric_range_problems, semantic_problems
from .imports import expand_imports
from .problems import problems_from_validation
from .schema import Scene
from .source import Loc, SourceMap, parse_yaml, read_yaml_file, yaml_path

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
        """The scene's name, else the file's stem made a safe file name (it names the
        frames): a stem the `name:` field would refuse keeps its letters, digits, '_', '-'
        and inner '.', and never starts with '.' (`.x.yaml` wrote hidden frames `.x.0000.exr`)."""
        return self.scene.name or safe_stem(self.path.stem)

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
        problems = problems_from_validation(exc, data, source, Scene)
        problems += salvaged_problems(exc, data, source, path.parent, problems, assets)
        raise SceneError(in_file_order(problems, file)) from None
    problems = semantic_problems(scene, path.parent, source, assets=assets) + numeric_range_problems(data, source, scene)
    if problems:
        raise SceneError(in_file_order(problems, file))
    return LoadedScene(scene=scene, path=path.resolve(), source=source, data=data)


def safe_stem(stem: str) -> str:
    """A file's stem as a scene name that is a safe, visible file name.

    >>> safe_stem(".x"), safe_stem("shot 010"), safe_stem("..."), safe_stem("a.b")
    ('x', 'shot_010', 'scene', 'a.b')
    """
    import re

    cleaned = re.sub(r"[^A-Za-z0-9_.\-]", "_", stem).lstrip(".-")
    return cleaned[:128] or "scene"


def in_file_order(problems: list[Problem], file: str) -> list[Problem]:
    """The scene file's problems by line and column, then those of other files (imports)."""
    return sorted(problems, key=lambda p: (p.file != file, p.file, p.line or 0, p.column or 0))


SALVAGE_ROUNDS = 8


def salvage(exc: ValidationError, data: dict[str, Any]) -> tuple[Scene, list[tuple[str | int, ...]]] | None:
    """The scene without the fields the schema refused (each dropped, or its enclosing
    mapping when a required field is missing), so that the semantic checks can run on the
    rest and every problem is reported at once. None when that would drop a whole item of a
    list (later references to it would be reported as unknown) or does not converge."""
    import copy

    from .problems import _strip_tags

    doc = copy.deepcopy(data)
    dropped: list[tuple[str | int, ...]] = []
    for _ in range(SALVAGE_ROUNDS):
        for err in exc.errors(include_url=False):
            loc = _strip_tags(tuple(err["loc"]), doc)
            if err["type"] == "missing" or (loc and isinstance(loc[-1], int)):
                loc = loc[:-1]  # the enclosing mapping goes, not the absent key
            if not loc or isinstance(loc[-1], int):
                return None  # a whole list item (or the document) would go
            node: Any = doc
            for part in loc[:-1]:
                try:
                    node = node[part]
                except (KeyError, IndexError, TypeError):
                    node = None
                    break
            if isinstance(node, dict) and loc[-1] in node:
                del node[loc[-1]]
                dropped.append(loc)
        try:
            return Scene.model_validate(doc), dropped
        except ValidationError as again:
            exc = again
    return None


def salvaged_problems(exc: ValidationError, data: dict[str, Any], source: SourceMap, base_dir: Path, found: list[Problem], assets: bool) -> list[Problem]:
    """The semantic problems (unknown material, missing asset, ...) of the part of the
    scene the schema accepted, beside the schema's own: found in one run, not one after
    the other. Problems at or below a dropped field, or at a path already reported, are
    left out (they are about what was dropped)."""
    saved = salvage(exc, data)
    if saved is None:
        return []
    scene, dropped = saved
    seen = {p.yaml_path for p in found}
    shown = [yaml_path(loc) for loc in dropped]
    out = []
    for p in semantic_problems(scene, base_dir, source, assets=assets):
        if p.yaml_path in seen or any(p.yaml_path == d or p.yaml_path.startswith(d + ".") or p.yaml_path.startswith(d + "[") for d in shown):
            continue
        out.append(p)
    return out


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """Merge `over` into a copy of `base`; nested mappings merge, everything else replaces."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out
