"""Render presets (configs/*.yaml, shipped as `motion.configs`) and the precedence rule:

    CLI flag  >  preset  >  scene file  >  built-in default

A preset may set `render:` and `output:` fields and `frame_count` (that many frames spread
evenly over the selected range, first and last included). A path to a YAML file works as a
preset name too.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .errors import Problem, SceneError, UsageError
from .scene.compiled import validate
from .scene.problems import problems_from_validation
from .scene.schema import OutputSettings, Preset, RenderSettings
from .scene.source import parse_yaml, read_yaml_file


def configs_dir() -> Path:
    """The built-in presets' folder: the `motion.configs` package (importlib.resources
    would add its imports to every command's start for a path the package knows)."""
    from .. import configs

    return Path(configs.__file__).parent


def preset_names() -> list[str]:
    """The built-in presets (configs/*.yaml, not farm.yaml)."""
    return sorted(p.name[:-5] for p in configs_dir().iterdir() if p.name.endswith(".yaml") and p.name != "farm.yaml")


def load_preset(name: str) -> tuple[Preset, str]:
    """A preset by name (configs/NAME.yaml) or path; returns it and its file name."""
    path = Path(name)
    if path.suffix.lower() in (".yaml", ".yml") or os.sep in name or (os.altsep and os.altsep in name):
        if not os.path.lexists(path):
            from .scene.checks import near_file

            raise UsageError(f"--preset {name}: file not found{near_file(name, Path.cwd())}")
        # bounded like a scene: a regular file within the size limit (docs/scene-format.md)
        text, file = read_yaml_file(path, "preset file"), str(path)
    else:
        entry = configs_dir() / f"{name}.yaml"
        if name == "farm" or not entry.is_file():
            from .scene.problems import closest

            close = closest(name, preset_names())
            hint = f"; did you mean '{close}'?" if close else ""
            raise UsageError(f"unknown preset '{name}'{hint} (available: {', '.join(preset_names())}, or a path to a .yaml file)")
        text, file = entry.read_text(), f"configs/{name}.yaml"
    data, source = parse_yaml(text, file)
    data = {} if data is None else data
    problems: list[Problem] = []
    preset = None
    try:
        preset = validate(Preset, data)  # the kept validators (scene/compiled.py): no schema built per process
    except ValidationError as exc:
        problems += problems_from_validation(exc, data, source, Preset)
    # check the sections against the scene format now, so a bad preset fails on its own
    # file, with every problem at once
    for key, model in (("render", RenderSettings), ("output", OutputSettings)):
        section = data.get(key) if isinstance(data, dict) else None
        if isinstance(section, dict) and section:
            try:
                validate(model, section)
            except ValidationError as exc:
                for p in problems_from_validation(exc, section, source.sub((key,)), model):
                    problems.append(Problem(p.file, p.line, p.column, f"{key}.{p.yaml_path}", p.message))
    out = data.get("output") if isinstance(data, dict) else None
    if isinstance(out, dict) and isinstance(out.get("filename"), str):
        from .scene.checks import output_pattern_problem

        reason = output_pattern_problem(out["filename"])
        if reason is not None:
            problems.append(source.problem(("output", "filename"), f"output pattern {out['filename']!r}: {reason}"))
    if problems or preset is None:
        raise SceneError(sorted(problems, key=lambda p: (p.line or 0, p.column or 0)))
    return preset, file


def overrides_from(preset: Preset | None, cli: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Nested overrides to merge over the scene document: the preset, then CLI flags."""
    out: dict[str, Any] = {}
    if preset is not None:
        for key in ("render", "output"):
            if getattr(preset, key):
                out[key] = dict(getattr(preset, key))
    for key, values in cli.items():
        section = {k: v for k, v in values.items() if v is not None}
        if section:
            out.setdefault(key, {}).update(section)
    return out


def spread(frames: list[int], count: int | None) -> list[int]:
    """`count` frames spread evenly over `frames` (first and last included)."""
    if count is None or count >= len(frames):
        return frames
    if count == 1:
        return [frames[0]]
    idx = [round(i * (len(frames) - 1) / (count - 1)) for i in range(count)]
    return [frames[i] for i in sorted(set(idx))]
