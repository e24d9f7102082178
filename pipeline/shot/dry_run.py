"""What a render would do, without rendering: `--dry-run` (the plan: frames, chunks,
executor, outputs) and `--check` (every selected frame complete, or exit 3)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..errors import IncompleteJobError
from ..farm.selection import format_frames
from .request import RenderRequest


def check_only(name: str, out_dir: Path, frames: list[int], todo: list[int], paths: dict[int, str], stale: dict[int, str] | None = None) -> dict[str, Any]:
    """`--check`: every selected frame must be complete and match (what a CI gather job
    runs before assembling deliverables); a stale frame is named with why."""
    if todo:
        absent = [f for f in todo if not os.path.exists(paths[f])]
        why = []
        if absent:
            why.append(f"missing {format_frames(absent)}")
        by_reason: dict[str, list[int]] = {}
        for f in todo:
            if f not in set(absent):
                by_reason.setdefault((stale or {}).get(f, "incomplete or made with other settings"), []).append(f)
        for reason, fs in by_reason.items():
            why.append(f"{format_frames(fs)} {reason}")
        raise IncompleteJobError(f"{out_dir}: {len(todo)} of {len(frames)} frames of {name} not complete: " + "; ".join(why))
    from ..farm.progress import log

    log.info(f"motion: {name}: all {len(frames)} frames ({format_frames(frames)}) complete in {out_dir}")
    return {"frames": len(frames), "complete": len(frames), "output_dir": str(out_dir)}


SETTINGS = ("resolution", "spp", "max_depth", "motion_blur", "shutter_samples", "denoise", "temporal", "filter", "seed_policy", "variant")
OUTPUT_SETTINGS = ("pixel_type", "compression", "aovs")


def resolved_settings(req: RenderRequest, loaded: Any, preset: Any) -> dict[str, dict[str, Any]]:
    """Each render setting as this job will use it and where it came from: `flag` beats
    `preset` beats `scene` beats `default` (docs: README, presets.py)."""
    from ..scene.source import parse_yaml, read_yaml_file

    try:
        raw, _ = parse_yaml(read_yaml_file(loaded.path, "scene file"), str(loaded.path))
    except Exception:  # the loader read it a moment ago; a file changed since says 'scene' nowhere
        raw = {}
    raw = raw if isinstance(raw, dict) else {}
    out: dict[str, dict[str, Any]] = {}
    for section, keys, flags in (("render", SETTINGS, req.render_overrides), ("output", OUTPUT_SETTINGS, req.output_overrides)):
        given = raw.get(section) if isinstance(raw.get(section), dict) else {}
        from_preset = getattr(preset, section, {}) if preset is not None else {}
        model = getattr(loaded.scene, section)
        for key in keys:
            if not hasattr(model, key):
                continue
            value = getattr(model, key)
            value = list(value) if isinstance(value, tuple) else value
            if flags.get(key) is not None:
                source = "flag"
            elif key in from_preset:
                source = f"preset {req.preset}"
            elif key in given:
                source = "scene"
            else:
                source = "default"
            out[key] = {"value": value, "from": source}
    return out


def plan(req: RenderRequest, loaded: Any, out_dir: Path, selected: list[int], frames: list[int], shard_spec: tuple[int, int] | None,
         skipped: list[int], chunk_list: list[list[int]], chunk_size: int, workers: int, threads: int | None, paths: dict[int, str],
         report_path: Path, stale: dict[int, str], wanted: Any, settings: dict[str, Any], estimate: dict[str, Any]) -> dict[str, Any]:
    """`--dry-run`: what this render would do (frames, chunks, executor, outputs, the
    resolved settings with where each came from, the frames it would replace and why, an
    estimate of its time), having loaded, validated and baked the scene and looked at the
    output folder; nothing is written."""
    first = paths[frames[0]] if frames else None
    deliver = {}
    if wanted:
        from ..deliverables import FORMATS
        from .deliver import next_version, read_manifest

        folder = out_dir / "deliver"
        made = read_manifest(folder, warn=lambda line: None)["deliverables"] if folder.is_dir() else {}
        for fmt in wanted.formats:  # the version a changed deliverable would get
            tag = wanted.tag(fmt)
            number = next_version(folder, loaded.name, tag, made.get(wanted.key(fmt)) or {})
            deliver[fmt] = str(folder / f"{loaded.name}_{tag}_v{number:03d}{FORMATS[fmt].suffix}")
    by_reason: dict[str, list[int]] = {}
    for f, why in sorted(stale.items()):
        by_reason.setdefault(why, []).append(f)
    return {
        "dry_run": True,
        "scene": str(loaded.path),
        "scene_name": loaded.name,
        "selection": format_frames(selected),
        "shard": f"{shard_spec[0]}/{shard_spec[1]}" if shard_spec else None,
        "frames": format_frames(frames),
        "frame_count": len(frames),
        "complete": format_frames(skipped),
        "replace": [{"frames": format_frames(fs), "reason": why} for why, fs in by_reason.items()],
        "settings": settings,
        "estimate": estimate,
        "to_render": format_frames([f for c in chunk_list for f in c]),
        "chunks": [format_frames(c) for c in chunk_list],
        "chunk_size": chunk_size,
        "executor": {"kind": "dask" if req.scheduler else "local", "workers": None if req.scheduler else min(workers, max(1, len(chunk_list))),
                     "threads": threads, "scheduler": req.scheduler},
        "outputs": {"output_dir": str(out_dir), "output_from": output_from(req, loaded), "first_frame": first, "last_frame": paths[frames[-1]] if frames else None,
                    "report": str(report_path), "deliverables": deliver,
                    "deliverables_left_out": dict(getattr(wanted, "skipped", {}) or {})},
    }


def output_from(req: RenderRequest, loaded: Any) -> str:
    """Where the output folder came from: -o, the scene's output.directory, or the default
    out/<name> under the current folder (not the scene's: a render from another folder
    does not find that folder's frames)."""
    if req.output_dir:
        return "-o"
    if loaded.scene.output.directory:
        return "the scene's output.directory, from the current folder"
    return f"out/<name> under the current folder {Path.cwd()}; -o to choose"


def plan_text(p: dict[str, Any]) -> str:
    """The plan as a few lines for a person."""
    ex = p["executor"]
    how = {"dask": f"dask at {ex['scheduler']}", "inline": f"inline (a small job: this process, no worker started) x {ex['threads']} threads"}.get(
        ex["kind"], f"local, {ex['workers']} worker processes x {ex['threads']} threads")
    lines = [
        f"plan for {p['scene_name']} ({p['scene']}): nothing rendered (--dry-run)",
        f"  frames:    {p['frames'] or 'none'} ({p['frame_count']})" + (f", shard {p['shard']} of {p['selection']}" if p["shard"] else ""),
        f"  complete:  {p['complete'] or 'none'} (kept)",
        *[f"  replace:   {r['frames']}: they {r['reason']}" for r in p["replace"]],
        f"  to render: {p['to_render'] or 'none'} in {len(p['chunks'])} chunks of <= {p['chunk_size']}",
        f"  executor:  {how}",
        "  settings:  " + ", ".join(f"{k} {_show(v['value'])} ({v['from']})" for k, v in p["settings"].items()),
        f"  estimate:  {_duration(p['estimate']['seconds'])} ({p['estimate']['basis']}; a warm frame {p['estimate']['warm_frame_s']:.2f} s)",
        f"  output:    {p['outputs']['output_dir']} ({p['outputs'].get('output_from', '-o')})",
        f"  frames to: {p['outputs']['first_frame']} .. {p['outputs']['last_frame']}",
        f"  report:    {p['outputs']['report']}",
    ]
    for fmt, path in p["outputs"]["deliverables"].items():
        lines.append(f"  {fmt}: {path} (the next version: made when its frames' pixels or its recipe changed)")
    for fmt, why in p["outputs"].get("deliverables_left_out", {}).items():
        lines.append(f"  {fmt}: not made: {why}")
    return "\n".join(lines)


def _show(value: Any) -> str:
    if isinstance(value, list) and len(value) == 2 and all(isinstance(v, int) for v in value):
        return f"{value[0]}x{value[1]}"
    if isinstance(value, list):
        return ",".join(map(str, value)) or "none"
    return str(value)


def _duration(seconds: float) -> str:
    """12.3 s, 4 min 05 s, 2 h 03 min."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"
