"""How long a job will take, said before it runs (`--dry-run`) and used for the first ETA.

The cost of a frame depends on the scene far more than on any count we can read from it
(depth, geometry, lights, denoiser), so the estimate is made from what this machine
measured: every finished run records, per scene, a warm frame's cost, the workers' cold
first frame and the farm's start-up (`$MOTION_CACHE_DIR/estimates.json`). A scene rendered
before is estimated from its own record, scaled by samples (pixels x spp) when the
settings differ; a scene never rendered here from this machine's median cost per sample
over the scenes it has rendered; a machine that has rendered nothing from built-in
figures measured on a 2-core Xeon (`basis` says which). bench/bench_estimate.py
measures the estimate against the real time on the examples.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import tempfile
from pathlib import Path
from typing import Any

HISTORY_FILE = "estimates.json"
MAX_SCENES = 200  # records kept (the oldest go first)
# Built-in figures (no run recorded on this machine yet), from a 2-core Xeon at the
# example scenes' presets: warm seconds per sample, seconds a frame beyond its samples, a
# worker's cold first frame beyond a warm one, and the farm's start-up.
DEFAULT_S_PER_SAMPLE = 3e-7
DEFAULT_FRAME_OVERHEAD_S = 0.08
DEFAULT_COLD_EXTRA_S = 1.2
DEFAULT_STARTUP_S = 1.5


def history_path() -> Path:
    """Where the measured costs are kept (beside the other caches)."""
    from ..cache import cache_root

    return cache_root() / HISTORY_FILE


def samples_of(scene: Any) -> int:
    """Camera samples of one frame: pixels x spp."""
    w, h = scene.render.resolution
    return int(w) * int(h) * int(scene.render.spp)


def _read() -> dict[str, Any]:
    try:
        data = json.loads(history_path().read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) and isinstance(data.get("scenes"), dict) else {}


def record(scene_name: str, settings_hash: str, samples: int, report: dict[str, Any]) -> None:
    """Keep what this run measured (best effort: an unwritable cache only loses the record)."""
    rows = [r for r in report.get("frames", []) if r.get("status") == "rendered" and "render_s" in r]
    if not rows:
        return
    cost = lambda r: float(r.get("setup_s", 0.0)) + float(r.get("render_s", 0.0)) + float(r.get("denoise_s", 0.0)) + float(r.get("write_s", 0.0))  # noqa: E731
    warm = [cost(r) for r in rows if not r.get("cold")]
    cold = [cost(r) for r in rows if r.get("cold")]
    if not warm:
        return  # a job of cold frames only (a one-frame check, `motion cache warm`) says nothing of a warm frame
    warm_s = statistics.median(warm)
    cold_extra = max(0.0, statistics.fmean(cold) - warm_s) if cold else 0.0
    workers = max(1, len(report.get("workers") or []) or 1)
    farm_s = float(report.get("totals", {}).get("farm_s", 0.0))
    startup = max(0.0, farm_s - sum(cost(r) for r in rows) / workers)
    data = _read() or {"version": 1, "scenes": {}}
    data["scenes"][scene_name] = {"settings_hash": settings_hash, "samples": samples, "warm_s": warm_s, "cold_extra_s": cold_extra,
                                  "startup_s": startup, "frames": len(rows), "workers": workers}
    while len(data["scenes"]) > MAX_SCENES:
        data["scenes"].pop(next(iter(data["scenes"])))
    try:
        path = history_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        with os.fdopen(fd, "w") as fh:
            json.dump(data, fh, indent=1)
        os.replace(tmp, path)
    except OSError:
        pass


def estimate(scene_name: str, settings_hash: str, samples: int, frames: int, workers: int, bake_s: float = 0.0) -> dict[str, Any]:
    """The job's expected wall time: bake, the farm's start-up, each worker's cold first
    frame, then warm frames shared among the workers. Returns the figures and their basis."""
    scenes = _read().get("scenes", {})
    mine = scenes.get(scene_name)
    startup, cold_extra = DEFAULT_STARTUP_S, DEFAULT_COLD_EXTRA_S
    if isinstance(mine, dict) and mine.get("samples"):
        scale = 1.0 if mine.get("settings_hash") == settings_hash else samples / float(mine["samples"])
        warm = float(mine["warm_s"]) * scale
        startup, cold_extra = float(mine["startup_s"]), float(mine["cold_extra_s"])
        basis = "this scene's last run" if scale == 1.0 else "this scene's last run, scaled by samples"
    else:
        rates = [float(s["warm_s"]) / float(s["samples"]) for s in scenes.values() if isinstance(s, dict) and s.get("samples")]
        if rates:
            warm = statistics.median(rates) * samples + DEFAULT_FRAME_OVERHEAD_S
            startup = statistics.median(float(s["startup_s"]) for s in scenes.values() if isinstance(s, dict) and "startup_s" in s)
            cold_extra = statistics.median(float(s["cold_extra_s"]) for s in scenes.values() if isinstance(s, dict) and "cold_extra_s" in s)
            basis = f"this machine's cost per sample over {len(rates)} scenes"
        else:
            warm = DEFAULT_S_PER_SAMPLE * samples + DEFAULT_FRAME_OVERHEAD_S
            basis = "built-in figures (no run recorded on this machine yet)"
    workers = max(1, min(workers, frames)) if frames else 1
    per_worker = math.ceil(frames / workers) if frames else 0
    render_s = (startup + cold_extra + per_worker * warm) if frames else 0.0
    return {"seconds": bake_s + render_s, "bake_s": bake_s, "warm_frame_s": warm, "cold_extra_s": cold_extra, "startup_s": startup,
            "per_frame_s": warm / workers, "basis": basis}
