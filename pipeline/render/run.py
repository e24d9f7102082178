"""Orchestrate one `motion render`: load and validate the scene with its overrides, select
frames, evaluate (bake) their motion once in this process, skip frames already complete,
render the rest, report, and assemble deliverables.

The farm stage (pipeline/farm) decides where the frames render; this module is the one
entry point the CLI calls.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import IncompleteJobError, UsageError
from ..presets import load_preset, overrides_from, spread
from ..scene.loader import load_scene
from .job import FrameResult, RenderJob, frame_done, render_frames, scene_hashes


@dataclass
class RenderRequest:
    scene: Path
    output_dir: Path | None = None
    frames_spec: str | None = None
    preset: str | None = None
    render_overrides: dict[str, Any] = field(default_factory=dict)
    cache: bool = True
    deliver: str | None = None
    resume: bool = True


def parse_frames(spec: str, first: int, last: int) -> list[int]:
    """'A-B' (inclusive) or a single frame. (The farm stage extends this grammar.)"""
    try:
        if "-" in spec[1:]:
            a, b = spec.split("-", 1) if not spec.startswith("-") else ("-" + spec[1:].split("-", 1)[0], spec[1:].split("-", 1)[1])
            lo, hi = int(a), int(b)
        else:
            lo = hi = int(spec)
    except ValueError:
        raise UsageError(f"--frames: expected A-B or N, got {spec!r}") from None
    if hi < lo:
        raise UsageError(f"--frames: range {spec!r} is reversed")
    return list(range(lo, hi + 1))


def run_render(req: RenderRequest) -> dict[str, Any]:
    preset, _ = load_preset(req.preset) if req.preset else (None, None)
    overrides = overrides_from(preset, {"render": req.render_overrides})
    loaded = load_scene(req.scene, overrides)
    scene = loaded.scene
    all_frames = list(scene.timeline.timeline().frames)
    frames = parse_frames(req.frames_spec, scene.timeline.first, scene.timeline.last) if req.frames_spec else spread(all_frames, preset.frame_count if preset else None)
    out_dir = Path(req.output_dir or scene.output.directory or Path("out") / loaded.name)
    scene_hash, settings_hash = scene_hashes(loaded)
    job = RenderJob(
        scene_path=str(loaded.path),
        overrides=overrides,
        output_dir=str(out_dir.resolve()),
        scene_hash=scene_hash,
        settings_hash=settings_hash,
        cache=req.cache,
        variant=scene.render.variant,
    )
    from .. import variant as variant_mod
    from .inputs import evaluate_frames

    choice = variant_mod.choose(scene.render.variant)  # probes in subprocesses; no drjit here
    if choice.fallback:
        variant_mod.warn_fallback(choice)

    t0 = time.perf_counter()
    inputs = evaluate_frames(loaded, frames)
    bake_s = time.perf_counter() - t0
    todo = [fi for fi in inputs if not (req.resume and frame_done(job, loaded, fi))]
    skipped = len(inputs) - len(todo)
    print(f"motion: {loaded.name}: {len(frames)} frames -> {out_dir} ({skipped} already complete)", file=sys.stderr)
    results: list[FrameResult] = []
    for fi in todo:
        (res,) = render_frames(job, [fi])
        results.append(res)
        state = "ok" if res.ok else f"FAILED: {res.error}"
        print(f"  frame {res.frame}: {state} ({'cold' if res.cold else 'warm'}, setup {res.setup_s:.3f}s, render {res.render_s:.3f}s)", file=sys.stderr)
    failed = [r for r in results if not r.ok]
    report = {
        "scene": str(loaded.path),
        "output_dir": str(out_dir),
        "frames": len(frames),
        "rendered": len(results) - len(failed),
        "skipped": skipped,
        "failed": [{"frame": r.frame, "error": r.error} for r in failed],
        "bake_seconds": bake_s,
        "results": [r.to_dict() for r in results],
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "render-report.json").write_text(json.dumps(report, indent=2))
    if failed:
        raise IncompleteJobError(f"{len(failed)} of {len(frames)} frames failed: " + ", ".join(f"{r.frame} ({r.error})" for r in failed[:5]))
    if req.deliver:
        from ..telecine.deliver import deliver, parse_formats

        deliver(out_dir, out_dir / "deliver", parse_formats(req.deliver))
    return report
