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

The cold costs are estimated apart: on a new machine they can be most of a first run
(docs/reruns.md, "The first run's estimate", has the measurements). A worker's first frame
compiles the renderer's kernels unless drjit's kernel cache holds them, and converts the
scene's assets unless the asset cache holds them. Kernels are mostly shared between
scenes, so what decides is whether the kernel cache is empty (a new machine, a fresh CI
runner, a cleared cache): then every kernel is compiled, estimated from this machine's
runs that did so, else a built-in figure. A run records whether it did. The first ETA (before frames are measured) counts
these cold costs down (farm/progress.py `overhead_s`) before the warm frames.
"""

from __future__ import annotations

import json
import math
import os
import statistics
from pathlib import Path
from typing import Any

from ..write_policy import write_best_effort

HISTORY_FILE = "estimates.json"
MAX_SCENES = 200  # scenes kept (the oldest go first)
MAX_RUNS = 8  # observations kept per scene (one per settings)
# A warm frame costs a fixed part (the frame's Python, its film and EXR, at small sizes the
# whole cost) plus a part per camera sample, plus the denoiser's part per pixel. Built-in
# figures (nothing recorded on this machine yet), measured on a 2-core AMD EPYC shared with
# other jobs (docs/reruns.md, "The first run's estimate"):
# ci-smoke frames (9,216 samples) 10-25 ms; preview frames (320x180, 16 spp, depth 4) render
# in 0.9-2.0 s; OIDN denoises 57,600-129,600 pixels in 4.4-5.0 us a pixel, one frame beside
# another worker's (the showcase at 480x270: 0.57 s; 960x540: 2.5 us a pixel); a worker's
# cold first frame (its scene build and asset conversion, and the kernels compiled when the
# kernel cache is empty: 14 of them for the examples) costs 2.5-4.6 s more than a warm one;
# two workers start in about 4 s (spawn, imports: 3.9 s measured).
DEFAULT_FRAME_OVERHEAD_S = 0.012
DEFAULT_S_PER_SAMPLE = 1.5e-6
DEFAULT_DENOISE_S_PER_PIXEL = 5.0e-6
DEFAULT_COLD_EXTRA_S = 3.0  # a cold first frame's extra cost with its kernels in the cache
DEFAULT_COMPILE_EXTRA_S = 4.5  # ... and with an empty kernel cache (every kernel compiled)
DEFAULT_STARTUP_S = 4.0
DEFAULT_INLINE_STARTUP_S = 0.1  # an inline job spawns nothing: the executor's own set-up
BIG_FRAME = 100_000  # samples above which a frame's cost says something about the machine's rate


def history_path() -> Path:
    """Where the measured costs are kept (beside the other caches)."""
    from ..cache import cache_root

    return cache_root() / HISTORY_FILE


def samples_of(scene: Any) -> int:
    """Camera samples of one frame: pixels x spp."""
    w, h = scene.render.resolution
    return int(w) * int(h) * int(scene.render.spp)


def denoised_pixels(scene: Any) -> int:
    """Pixels the denoiser runs over in one frame (0 when it is off)."""
    w, h = scene.render.resolution
    return int(w) * int(h) if scene.render.denoise != "off" else 0


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


def record(scene_name: str, settings_hash: str, samples: int, report: dict[str, Any], compiled_all: bool = False) -> None:
    """Keep what this run measured (best effort: an unwritable cache only loses the record).
    `compiled_all`: the run started with an empty kernel cache (its estimate's
    `compiles_kernels`); it counts as compiling every kernel if its cold frames compiled any."""
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
    compiled = compiled_all and any(int(r.get("kernels_compiled", 0) or 0) > 0 for r in rows if r.get("cold"))
    data = _read() or {"version": 2, "scenes": {}}
    runs = [r for r in data["scenes"].pop(scene_name, []) if isinstance(r, dict) and r.get("settings_hash") != settings_hash]
    inline = (report.get("executor") or {}).get("kind") == "inline" if isinstance(report.get("executor"), dict) else False
    runs.append({"settings_hash": settings_hash, "samples": samples, "warm_s": warm_s, "cold_extra_s": cold_extra, "startup_s": startup,
                 "compiled": compiled, "inline": inline})
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


# A kernel cache holding less than this has none of a render's kernels: the variant probe
# leaves its own few (5 files, 17 KB); one example rendered leaves about 150 KB.
EMPTY_KERNEL_CACHE_BYTES = 64 * 1024


def kernel_bytes() -> int:
    """Bytes of drjit's files in its kernel cache (`cache.kernel_files`: another's file in a
    shared $DRJIT_CACHE_DIR is no kernel); 0 when it is missing or unreadable."""
    from ..cache import kernel_files

    total = 0
    for path in kernel_files():
        try:
            total += path.stat().st_size
        except OSError:
            continue  # a sweep took it
    return total


def cold_extra_of(runs: list[dict[str, Any]], everything: list[dict[str, Any]], compiles: bool) -> tuple[float, str]:
    """A worker's cold first frame's extra cost, and what it comes from. With an empty
    kernel cache (`compiles`): from this machine's runs that compiled every kernel, else
    the built-in figure. With kernels in the cache (most are shared between scenes: a new
    scene compiles a few seconds' worth): this scene's last run unless it compiled them
    all, else this machine's runs that did not, else at most what a run that compiled
    them all paid."""
    def fig(r: dict[str, Any]) -> float:
        return float(r.get("cold_extra_s", 0.0) or 0.0)

    if compiles:
        seen = [fig(r) for r in everything if r.get("compiled")]
        if seen:
            return statistics.median(seen), f"an empty kernel cache: every kernel compiled, as in {len(seen)} runs here"
        return DEFAULT_COMPILE_EXTRA_S, "an empty kernel cache: every kernel compiled (built-in figure)"
    if runs and not runs[-1].get("compiled"):
        return fig(runs[-1]), "kernels from the cache"
    cached = [fig(r) for r in everything if not r.get("compiled")]
    if cached:
        return statistics.median(cached), "kernels from the cache"
    # only runs that compiled everything: a cold frame from the cache costs at most what theirs did
    compiled = [fig(r) for r in (runs or everything) if r.get("compiled")]
    return min([DEFAULT_COLD_EXTRA_S, *compiled]), "kernels from the cache"


def startup_of(runs: list[dict[str, Any]], everything: list[dict[str, Any]], inline: bool) -> float:
    """The start-up of a job run by spawned workers, or inline in this process (`inline`):
    this scene's last such run, else the median of this machine's, else the built-in figure
    (an inline job starts no process: its scene build is in its cold frame)."""
    same = lambda r: bool(r.get("inline", False)) == inline  # noqa: E731
    mine = [r for r in runs if same(r)]
    if mine:
        return float(mine[-1]["startup_s"])
    known = [float(r["startup_s"]) for r in everything if same(r) and "startup_s" in r]
    if known:
        return statistics.median(known)
    return DEFAULT_INLINE_STARTUP_S if inline else DEFAULT_STARTUP_S


def estimate(scene_name: str, settings_hash: str, samples: int, frames: int, workers: int, bake_s: float = 0.0, denoise_pixels: int = 0) -> dict[str, Any]:
    """The job's expected wall time on spawned workers: bake, their start-up, each worker's
    cold first frame (every kernel compiled when the kernel cache is empty: `cold_extra_of`),
    then warm frames shared among the workers. Returns the figures and their basis, and
    the start-up an inline run would have instead (`run_inline`)."""
    scenes = _read().get("scenes", {})
    runs = [r for r in scenes.get(scene_name, []) if isinstance(r, dict) and r.get("samples")]
    everything = [r for rs in scenes.values() for r in rs if isinstance(r, dict)]
    rate = machine_rate(scenes)
    compiles = kernel_bytes() < EMPTY_KERNEL_CACHE_BYTES  # a new machine, a fresh CI runner, a cleared cache
    if runs:
        warm, basis = warm_frame(runs, settings_hash, samples, rate)
    else:
        warm = DEFAULT_FRAME_OVERHEAD_S + rate * samples + DEFAULT_DENOISE_S_PER_PIXEL * denoise_pixels
        if everything:
            basis = f"this machine's cost per sample ({len(everything)} runs recorded)"
        else:
            basis = "built-in figures (no run recorded on this machine yet)"
    cold_extra, cold_basis = cold_extra_of(runs, everything, compiles)
    figures = {"frames": frames, "bake_s": bake_s, "warm_frame_s": warm, "cold_extra_s": cold_extra, "compiles_kernels": compiles,
               "inline_startup_s": startup_of(runs, everything, inline=True), "basis": f"{basis}; {cold_basis}"}
    return _on(figures, workers, startup_of(runs, everything, inline=False))


def run_inline(cost: dict[str, Any]) -> dict[str, Any]:
    """`estimate`'s figures for the job rendered inline, in this process: one worker, and no
    worker to start."""
    return _on(cost, 1, cost["inline_startup_s"])


def _on(figures: dict[str, Any], workers: int, startup: float) -> dict[str, Any]:
    """The figures with the job's time on `workers` that take `startup` to start."""
    frames, warm = figures["frames"], figures["warm_frame_s"]
    workers = max(1, min(workers, frames)) if frames else 1
    per_worker = math.ceil(frames / workers) if frames else 0
    render_s = (startup + figures["cold_extra_s"] + per_worker * warm) if frames else 0.0
    return {**figures, "seconds": figures["bake_s"] + render_s, "startup_s": startup, "per_frame_s": warm / workers}
