"""What a render would do, without rendering: `--dry-run` (the plan: frames, chunks,
executor, outputs) and `--check` (every selected frame complete, or exit 3)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..errors import IncompleteJobError
from ..farm.frames import format_frames
from .request import RenderRequest


def check_only(name: str, out_dir: Path, frames: list[int], todo: list[int], paths: dict[int, str]) -> dict[str, Any]:
    """`--check`: every selected frame must be complete and match (what a CI gather job
    runs before assembling deliverables)."""
    if todo:
        absent = [f for f in todo if not os.path.exists(paths[f])]
        stale = [f for f in todo if f not in set(absent)]
        why = []
        if absent:
            why.append(f"missing {format_frames(absent)}")
        if stale:
            why.append(f"incomplete or made with other settings {format_frames(stale)}")
        raise IncompleteJobError(f"{out_dir}: {len(todo)} of {len(frames)} frames of {name} not complete: " + "; ".join(why))
    from ..farm.progress import log

    log.info(f"motion: {name}: all {len(frames)} frames ({format_frames(frames)}) complete in {out_dir}")
    return {"frames": len(frames), "complete": len(frames), "output_dir": str(out_dir)}


def plan(req: RenderRequest, loaded: Any, out_dir: Path, selected: list[int], frames: list[int], shard_spec: tuple[int, int] | None,
         skipped: list[int], chunk_list: list[list[int]], chunk_size: int, workers: int, threads: int | None, paths: dict[int, str],
         report_path: Path) -> dict[str, Any]:
    """`--dry-run`: what this render would do (frames, chunks, executor, outputs), having
    loaded, validated and baked the scene and looked at the output folder; nothing is
    written."""
    from ..telecine.deliver import parse_formats

    first = paths[frames[0]] if frames else None
    deliver = {}
    if req.deliver:
        prefix = Path(first).name.split(".")[0] if first else loaded.name
        names = {"24p": f"{prefix}_24p.mov", "60i": f"{prefix}_60i.mov", "50i": f"{prefix}_50i.mov", "review": f"{prefix}_review.mp4", "contact": f"{prefix}_contact.png"}
        deliver = {fmt: str(out_dir / "deliver" / names[fmt]) for fmt in parse_formats(req.deliver)}
    return {
        "dry_run": True,
        "scene": str(loaded.path),
        "scene_name": loaded.name,
        "selection": format_frames(selected),
        "shard": f"{shard_spec[0]}/{shard_spec[1]}" if shard_spec else None,
        "frames": format_frames(frames),
        "frame_count": len(frames),
        "complete": format_frames(skipped),
        "to_render": format_frames([f for c in chunk_list for f in c]),
        "chunks": [format_frames(c) for c in chunk_list],
        "chunk_size": chunk_size,
        "executor": {"kind": "dask" if req.scheduler else "local", "workers": None if req.scheduler else min(workers, max(1, len(chunk_list))),
                     "threads": threads, "scheduler": req.scheduler},
        "outputs": {"output_dir": str(out_dir), "first_frame": first, "last_frame": paths[frames[-1]] if frames else None,
                    "report": str(report_path), "deliverables": deliver},
    }


def plan_text(p: dict[str, Any]) -> str:
    """The plan as a few lines for a person."""
    ex = p["executor"]
    how = f"dask at {ex['scheduler']}" if ex["kind"] == "dask" else f"local, {ex['workers']} worker processes x {ex['threads']} threads"
    lines = [
        f"plan for {p['scene_name']} ({p['scene']}): nothing rendered (--dry-run)",
        f"  frames:    {p['frames'] or 'none'} ({p['frame_count']})" + (f", shard {p['shard']} of {p['selection']}" if p["shard"] else ""),
        f"  complete:  {p['complete'] or 'none'} (kept)",
        f"  to render: {p['to_render'] or 'none'} in {len(p['chunks'])} chunks of <= {p['chunk_size']}",
        f"  executor:  {how}",
        f"  frames to: {p['outputs']['first_frame']} .. {p['outputs']['last_frame']}",
        f"  report:    {p['outputs']['report']}",
    ]
    for fmt, path in p["outputs"]["deliverables"].items():
        lines.append(f"  {fmt}: {path}")
    return "\n".join(lines)
