"""How long a job will take, said before it runs (`--dry-run`) and used for the first ETA.

The cost of a frame depends on the scene far more than on any count we can read from it
(depth, geometry, lights, denoiser), so the estimate is made from what this machine
measured: every finished run records, per scene and settings, a warm frame's cost, the
workers' cold first frame and the farm's start-up (`$MOTION_CACHE_DIR/estimates.json`).
A warm frame is a fixed part plus a part per camera sample (pixels x spp): a scene rendered
before with these settings is estimated from that run; at two or more sample counts from
the line through them; at one from that run shifted by this machine's cost per sample
(measured on frames big enough for it to show); a scene never rendered here from the
machine's cost per sample; a machine that has rendered nothing from built-in figures
(`basis` says which). bench/bench_estimate.py measures the estimate against the real time
on the examples.
"""

from __future__ import annotations

import json
import math
import statistics
from pathlib import Path
from typing import Any

from ..files import write_best_effort

HISTORY_FILE = "estimates.json"
MAX_SCENES = 200  # scenes kept (the oldest go first)
MAX_RUNS = 8  # observations kept per scene (one per settings)
# A warm frame costs a fixed part (the frame's Python, its film and EXR, at small sizes the
# whole cost) plus a part per camera sample. Built-in figures (nothing recorded on this
# machine yet) from a 2-core Xeon: ci-smoke frames (9,216 samples) take 10-15 ms, preview
# frames (921,600 samples, denoised) about 0.15 s.
DEFAULT_FRAME_OVERHEAD_S = 0.012
DEFAULT_S_PER_SAMPLE = 1.5e-7
DEFAULT_COLD_EXTRA_S = 0.8
DEFAULT_STARTUP_S = 0.8
BIG_FRAME = 100_000  # samples above which a frame's cost says something about the machine's rate


def history_path() -> Path:
    """Where the measured costs are kept (beside the other caches)."""
    from ..cache import cache_root

    return cache_root() / HISTORY_FILE


def samples_of(scene: Any) -> int:
    """Camera samples of one frame: pixels x spp."""
    w, h = scene.render.resolution
    return int(w) * int(h) * int(scene.render.spp)


_NUMBERS = ("samples", "warm_s", "cold_extra_s", "startup_s")  # of each run: finite, not negative


def _run_ok(run: Any) -> bool:
    """Whether a recorded run is one `record` wrote: its settings hash and its numbers."""
    if not isinstance(run, dict) or not isinstance(run.get("settings_hash"), str):
        return False
    values = [run.get(k) for k in _NUMBERS]
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0 for v in values)


def _read() -> dict[str, Any]:
    """The recorded costs, or {} when there are none. A history that is not one this code
    wrote (a FIFO, another type, a bad number, deep nesting) is discarded with one warning
    line (`limits.read_json_record`); the next finished run writes a new one."""
    from ..limits import read_json_record

    path = history_path()
    data = read_json_record(path, "cost history", limit=16 << 20, depth=8)
    if data is None:
        return {}
    if data.get("version") != 2:
        return {}  # another version's history: replaced by the next run, as before
    scenes = data.get("scenes")
    if not (isinstance(scenes, dict) and all(isinstance(runs, list) and all(_run_ok(r) for r in runs) for runs in scenes.values())):
        import logging

        logging.getLogger("motion").warning(f"motion: warning: {path}: cost history discarded (not the record expected); it is made again")
        return {}
    return data


def record(scene_name: str, settings_hash: str, samples: int, report: dict[str, Any]) -> None:
    """Keep what this run measured (best effort: an unwritable cache only loses the record)."""
    rows = [r for r in report.get("frames", []) if r.get("status") == "rendered" and "render_s" in r]
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
    data = _read() or {"version": 2, "scenes": {}}
    runs = [r for r in data["scenes"].pop(scene_name, []) if isinstance(r, dict) and r.get("settings_hash") != settings_hash]
    runs.append({"settings_hash": settings_hash, "samples": samples, "warm_s": warm_s, "cold_extra_s": cold_extra, "startup_s": startup})
    data["scenes"][scene_name] = runs[-MAX_RUNS:]
    while len(data["scenes"]) > MAX_SCENES:
        data["scenes"].pop(next(iter(data["scenes"])))
    write_best_effort(history_path(), json.dumps(data, indent=1).encode())  # lost: the next estimate uses older runs


def machine_rate(scenes: dict[str, Any]) -> float:
    """Seconds per sample on this machine: the median over recorded frames big enough for
    their samples to dominate, else the built-in figure."""
    rates = [(float(r["warm_s"]) - DEFAULT_FRAME_OVERHEAD_S) / float(r["samples"]) for runs in scenes.values() for r in runs
             if isinstance(r, dict) and float(r.get("samples", 0)) >= BIG_FRAME and float(r["warm_s"]) > DEFAULT_FRAME_OVERHEAD_S]
    return statistics.median(rates) if rates else DEFAULT_S_PER_SAMPLE


def warm_frame(runs: list[dict[str, Any]], settings_hash: str, samples: int, rate: float) -> tuple[float, str]:
    """A warm frame's cost for this scene from its recorded runs: the same settings as
    measured; two or more sample counts fitted by a line (fixed part + per sample); one
    run shifted by the machine's rate for the samples added or removed."""
    same = [r for r in runs if r.get("settings_hash") == settings_hash]
    if same:
        return float(same[-1]["warm_s"]), "this scene's last run with these settings"
    points = sorted({int(r["samples"]): float(r["warm_s"]) for r in runs}.items())
    if len(points) >= 2:
        xs, ys = [float(x) for x, _ in points], [y for _, y in points]
        mx, my = statistics.fmean(xs), statistics.fmean(ys)
        b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)
        b = max(b, 0.0)
        a = max(0.0, my - b * mx)
        return a + b * samples, f"this scene's runs at {len(points)} sample counts"
    s0, w0 = points[0]
    return max(DEFAULT_FRAME_OVERHEAD_S, w0 + rate * (samples - s0)), "this scene's last run, rescaled by this machine's cost per sample"


def estimate(scene_name: str, settings_hash: str, samples: int, frames: int, workers: int, bake_s: float = 0.0) -> dict[str, Any]:
    """The job's expected wall time: bake, the farm's start-up, each worker's cold first
    frame, then warm frames shared among the workers. Returns the figures and their basis."""
    scenes = _read().get("scenes", {})
    runs = [r for r in scenes.get(scene_name, []) if isinstance(r, dict) and r.get("samples")]
    rate = machine_rate(scenes)
    if runs:
        warm, basis = warm_frame(runs, settings_hash, samples, rate)
        startup, cold_extra = float(runs[-1]["startup_s"]), float(runs[-1]["cold_extra_s"])
    else:
        everything = [r for rs in scenes.values() for r in rs if isinstance(r, dict)]
        warm = DEFAULT_FRAME_OVERHEAD_S + rate * samples
        if everything:
            startup = statistics.median(float(r["startup_s"]) for r in everything)
            cold_extra = statistics.median(float(r["cold_extra_s"]) for r in everything)
            basis = f"this machine's cost per sample ({len(everything)} runs recorded)"
        else:
            startup, cold_extra = DEFAULT_STARTUP_S, DEFAULT_COLD_EXTRA_S
            basis = "built-in figures (no run recorded on this machine yet)"
    workers = max(1, min(workers, frames)) if frames else 1
    per_worker = math.ceil(frames / workers) if frames else 0
    render_s = (startup + cold_extra + per_worker * warm) if frames else 0.0
    return {"seconds": bake_s + render_s, "bake_s": bake_s, "warm_frame_s": warm, "cold_extra_s": cold_extra, "startup_s": startup,
            "per_frame_s": warm / workers, "basis": basis}
