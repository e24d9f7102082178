"""Imports: glTF 2.0 and USD files expanded into the records a hand-written scene has
(docs/imports.md).

`expand_imports` runs in the scene stage, between YAML parsing and validation: each
`imports:` entry is read (pygltflib for glTF, usd-core for USD) and becomes plain
records (objects, materials, lights, the camera) appended to the document, with keyframe
motion, skins and morph targets in the scene format's own terms. Meshes, textures and
skin weights go to the content-addressed asset cache. Nothing downstream knows where a
record came from; only the source map does: a problem in an imported record is reported
at the asset file and node (or prim), or at the override in the scene file that set it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import Problem, SceneError
from .expansion import Expansion, ImportFileError, Origin, SpecError

if TYPE_CHECKING:
    from ..source import SourceMap

__all__ = ["ImportFileError", "SpecError", "Origin", "Expansion", "expand_imports"]


# Keys an override may not change: they say what the record is.
FIXED_KEYS = ("name", "shape", "file", "type")


def expand_imports(data: dict[str, Any], source: "SourceMap", base_dir: Path) -> tuple[dict[str, Any], "SourceMap"]:
    """The scene document with every `imports:` entry expanded into records, and a source
    map that locates problems in them. Returns `data` and `source` unchanged when the
    scene imports nothing. Raises SceneError (located) for bad entries or asset files."""
    raw = data.get("imports")
    if not raw:
        return data, source
    from pydantic import ValidationError

    from ...cache import check_cache_root
    from .. import compiled
    from ..problems import problems_from_validation
    from .spec import ImportList

    check_cache_root()  # the readers convert into it: a cache root that is a file, or not writable, is one line

    try:
        specs = compiled.validate(ImportList, {"imports": raw}).imports
    except ValidationError as exc:
        raise SceneError(problems_from_validation(exc, {"imports": raw}, source, ImportList)) from None

    out = dict(data)
    lists = [[] if out.get(key) is None else out[key] for key in ("objects", "materials", "lights")]
    if not all(isinstance(x, list) for x in lists):
        return data, source  # the schema reports the malformed lists
    objects, materials, lights = (list(x) for x in lists)
    origins: dict[tuple[str, int], Origin] = {}
    camera_origin: Origin | None = None
    problems: list[Problem] = []
    chosen_camera: tuple[dict[str, Any], Origin] | None = None
    for i, spec in enumerate(specs):
        path = base_dir / spec.file
        shown = str(path) if not Path(spec.file).is_absolute() else spec.file
        if not path.is_file():
            problems.append(source.problem(("imports", i, "file"), f"file not found: {spec.file} (relative to {base_dir})"))
            continue
        try:
            expansion = _read(path, shown, spec, i, base_dir)
        except SceneError as exc:
            problems.extend(exc.problems)
            continue
        except SpecError as exc:
            problems.append(source.problem(("imports", i, exc.field), str(exc)))
            continue
        problems.extend(_apply_overrides(spec, i, expansion, source))
        for kind, target, recs in (("objects", objects, expansion.objects), ("materials", materials, expansion.materials), ("lights", lights, expansion.lights)):
            for rec, origin in recs:
                origins[(kind, len(target))] = origin
                target.append(rec)
        chosen_camera = _choose_camera(spec, i, expansion, chosen_camera, "camera" in data, source, problems)
    if problems:
        raise SceneError(problems)
    if chosen_camera is not None:
        out["camera"], camera_origin = _refined_camera(chosen_camera, data.get("camera"))
    out["objects"], out["materials"], out["lights"] = objects, materials, lights
    from .sourcemap import ImportedSourceMap

    return out, ImportedSourceMap(source.file, source.positions, origins, camera_origin)


def _apply_overrides(spec: Any, index: int, expansion: Expansion, source: "SourceMap") -> list[Problem]:
    """The entry's overrides, by (prefixed) name, applied over the imported objects and
    lights in `expansion` (each overridden key located at the override); the problems of
    those that name nothing imported or change what a record is (FIXED_KEYS)."""
    problems: list[Problem] = []
    # (kept records that are not mappings, or whose name is not text, never get here: memo._recall makes them again)
    by_name = {rec["name"]: (kind, j) for kind, recs in (("objects", expansion.objects), ("lights", expansion.lights))
               for j, (rec, _) in enumerate(recs) if isinstance(rec, dict) and isinstance(rec.get("name"), str)}
    for name, over in spec.overrides.items():
        oloc = ("imports", index, "overrides", name)
        if name not in by_name:
            import difflib

            close = difflib.get_close_matches(name, [n for n in by_name if n], n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            problems.append(source.problem(oloc, f"no imported object or light named '{name}'{hint}", key=True))
            continue
        fixed = [k for k in over if k in FIXED_KEYS]
        if fixed:
            problems.append(source.problem((*oloc, fixed[0]), f"an override cannot change '{fixed[0]}'", key=True))
            continue
        kind, j = by_name[name]
        recs = expansion.objects if kind == "objects" else expansion.lights
        rec, origin = recs[j]
        rec = {**rec, **over}
        keys = {**origin.yaml_keys, **{k: (*oloc, k) for k in over}}
        recs[j] = (rec, Origin(origin.file, origin.where, keys, origin.default))
    return problems


def _choose_camera(
    spec: Any, index: int, expansion: Expansion, chosen: tuple[dict[str, Any], Origin] | None, scene_has_camera: bool, source: "SourceMap", problems: list[Problem]
) -> tuple[dict[str, Any], Origin] | None:
    """The shot's camera after this entry: the one it names (a problem in `problems` if
    there is none), else the first imported when the scene has none and none was chosen."""
    if spec.camera is not None:
        found = [(rec, o) for name, rec, o in expansion.cameras if name == spec.camera]
        if not found:
            names = ", ".join(n for n, _, _ in expansion.cameras) or "none"
            problems.append(source.problem(("imports", index, "camera"), f"no camera on node '{spec.camera}' in {spec.file} (cameras on: {names})"))
            return chosen
        return found[0]
    if chosen is None and expansion.cameras and not scene_has_camera:
        return (expansion.cameras[0][1], expansion.cameras[0][2])
    return chosen


def _refined_camera(chosen: tuple[dict[str, Any], Origin], user: Any) -> tuple[dict[str, Any], Origin]:
    """The imported camera record with the scene file's own camera keys over it (shutter,
    fov, ...), and its origin; a scene that places the camera itself, in world space, drops
    the imported transform (and parent)."""
    rec, origin = chosen
    if isinstance(user, dict):
        rec = {**rec, **user}
        if ("position" in user or "look_at" in user) and "transform" not in user:
            rec.pop("transform", None)
            if "parent" not in user:
                rec.pop("parent", None)
        origin = Origin(origin.file, origin.where, {k: ("camera", k) for k in user})
    return rec, origin


def _read(path: Path, shown: str, spec: Any, index: int, base_dir: Path) -> Expansion:
    """The glTF or USD reader's records of one import, kept between loads (memo.py; a USD
    stage's layers are confined to the scene's folder, `base_dir`)."""
    from .memo import read_import

    return read_import(path, shown, spec, index, base_dir)
