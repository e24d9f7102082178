"""Load a scene: YAML (safely, with source positions) -> validated, immutable `Scene`.

Every problem becomes one `Problem(file, line, column, yaml_path, message)`; all of them
are collected and raised together as one `SceneError`, before any long job starts. The
YAML reading and source positions are `source.py`, pydantic errors -> problems
`problems.py`, imports `imports/`, the checks a schema cannot express `checks.py`.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from pydantic import ValidationError

from ..errors import Problem, SceneError
from .checks import numeric_range_problems, semantic_problems
from . import compiled
from .imports import expand_imports
from .problems import problems_from_validation
from .schema import Scene
from .source import Loc, SourceMap, parse_kept, read_yaml_file, yaml_path

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

    @functools.cached_property
    def objects_by_name(self) -> dict[str, Any]:
        """The scene's objects by name, made once (the renderer looks every mover up: a scan
        of the list each time cost 0.09 s of a 1,000-mover first frame)."""
        return {o.name: o for o in self.scene.objects}

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
    data, source = parse_kept(text, file)
    if data is None:
        raise SceneError([Problem(file, 1, 1, "", "the scene file is empty; expected a mapping with at least 'camera'")])
    if not isinstance(data, dict):
        raise SceneError([source.problem((), f"expected a mapping at the top level, got {type(data).__name__}")])
    if overrides:
        data = deep_merge(data, overrides)
    data, source = expand_imports(data, source, path.parent)
    try:
        scene = compiled.validate(Scene, data)
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
    cleaned = re.sub(r"[^A-Za-z0-9_.\-]", "_", stem).lstrip(".-")
    return cleaned[:128] or "scene"


def in_file_order(problems: list[Problem], file: str) -> list[Problem]:
    """The scene file's problems by line and column, then those of other files (imports)."""
    return sorted(problems, key=lambda p: (p.file != file, p.file, p.line or 0, p.column or 0))


SALVAGE_ROUNDS = 8
# A named item of these lists that the schema refuses whole (an unknown or missing kind, a
# required field missing) is replaced by a stand-in of the same name at the same index, so
# that references to it still resolve and the items after it keep their place.
STAND_INS: dict[str, tuple[str, str]] = {"objects": ("shape", "empty"), "materials": ("type", "diffuse"), "lights": ("type", "constant")}
KEPT = ("parent", "transform")  # what a stand-in keeps of the item (its name aside)
UNNAMED = "_unnamed_"  # the prefix of a stand-in name for an item missing its own


def salvage(exc: ValidationError, data: dict[str, Any], source: SourceMap | None = None) -> tuple[Scene, list[tuple[str | int, ...]], list[Problem]] | None:
    """The scene without the fields the schema refused, so that the semantic checks can
    run on the rest and every problem is reported at once: a refused field is dropped (its
    enclosing mapping when a required field is missing; a list item's enclosing list key);
    a named item of `objects`, `materials` or `lights` refused whole keeps its name,
    parent, transform and place as a stand-in (an unknown kind becomes the closest known one, as the message
    suggests; a missing name a unique placeholder). Returns the scene and the dropped
    paths, or None when that does not converge."""
    import copy

    from .problems import _strip_tags, closest

    doc = copy.deepcopy(data)
    dropped: list[tuple[str | int, ...]] = []
    guessed: list[tuple[str | int, ...]] = []
    later: list[Problem] = []

    def stand_in(loc: tuple[str | int, ...], err: Any) -> bool:
        """Replace or mend the top-level list item at `loc` (a named kind); False if it is not one."""
        if len(loc) != 2 or loc[0] not in STAND_INS or not isinstance(loc[1], int):
            return False
        items = doc.get(loc[0])
        if not isinstance(items, list) or not loc[1] < len(items):
            return False
        item = items[loc[1]]
        tag, fallback = STAND_INS[loc[0]]
        name = item.get("name") if isinstance(item, dict) else None
        if not isinstance(name, str):
            name = f"{UNNAMED}{loc[0]}_{loc[1]}"
        kind = err["type"]
        if isinstance(item, dict) and kind == "missing" and tuple(err["loc"])[-1] == "name":
            item["name"] = name  # keep the item and check the rest of it
            return True
        if isinstance(item, dict) and kind == "union_tag_invalid":
            options = [t.strip().strip("'") for t in str(err.get("ctx", {}).get("expected_tags", "")).split(",")]
            close = closest(item.get(tag), options, cutoff=0.5)
            if close:
                item[tag] = close  # checked as the kind the message suggests; what that kind refuses goes next round
                guessed.append(loc)
                return True
        kept = {k: item[k] for k in KEPT if isinstance(item, dict) and k in item}  # what refers across items; a bad one goes next round
        items[loc[1]] = {**kept, "name": name, tag: fallback}
        dropped.append(loc)
        return True

    for _ in range(SALVAGE_ROUNDS):
        for err in exc.errors(include_url=False):
            loc = _strip_tags(tuple(err["loc"]), doc)
            if err["type"] == "missing" and loc and isinstance(loc[-1], str):
                loc = loc[:-1]  # the enclosing mapping goes, not the absent key
            if stand_in(loc, err):
                continue
            while loc and isinstance(loc[-1], int):
                loc = loc[:-1]  # an item of another list: its list goes (an index would shift the rest)
            if not loc:
                return None  # the document itself
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
            return compiled.validate(Scene, doc), dropped, later
        except ValidationError as again:
            exc = again
        if source is not None and guessed:
            later += [p for p in problems_from_validation(exc, doc, source, Scene)
                      if any(p.yaml_path.startswith(yaml_path(g) + ".") for g in guessed) and p.yaml_path not in {q.yaml_path for q in later}]
    return None


def salvaged_problems(exc: ValidationError, data: dict[str, Any], source: SourceMap, base_dir: Path, found: list[Problem], assets: bool) -> list[Problem]:
    """The semantic and numeric-range problems (unknown material, missing asset, a number
    float32 cannot hold, ...) of the part of the scene the schema accepted, and the schema's
    problems inside an item of a misspelt kind, beside the schema's own: found in one run,
    not one after the other. Problems at or below a dropped
    field, at a path already reported, or naming a stand-in, are left out (they are about
    what was dropped)."""
    saved = salvage(exc, data, source)
    if saved is None:
        return []
    scene, dropped, later = saved
    seen = {p.yaml_path for p in found}
    out = [p for p in later if p.yaml_path not in seen]  # the fields of an item checked as a suggested kind
    seen |= {p.yaml_path for p in out}
    shown = [yaml_path(loc) for loc in dropped]
    for p in semantic_problems(scene, base_dir, source, assets=assets) + numeric_range_problems(data, source, scene):
        if p.yaml_path in seen or f"'{UNNAMED}" in p.message or any(p.yaml_path == d or p.yaml_path.startswith(d + ".") or p.yaml_path.startswith(d + "[") for d in shown):
            continue
        seen.add(p.yaml_path)
        # a list of names ("defined: a, b") leaves the placeholders out
        out.append(dataclasses.replace(p, message=re.sub(rf"{UNNAMED}[a-z]+_\d+(, )?", "", p.message)) if UNNAMED in p.message else p)
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
