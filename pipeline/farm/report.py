"""`render-report.json`: per frame (worker, cold/warm, setup/render/write seconds,
attempts, errors), per worker (first-frame cost, frames, failures, exclusion), totals."""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from ..errors import DiskFaultError, MotionError, UsageError
from ..frame_output import disk_fault, write_atomic
from ..render.worker.job import RenderJob
from ..scene.loader import LoadedScene
from .config import FarmConfig
from .selection import format_frames
from .states import FINAL_FRAME_STATES

if TYPE_CHECKING:  # (a rerun that renders nothing writes its report without the scheduler's modules)
    from .scheduler import Scheduler


def _times_on_disk(job: RenderJob, loaded: LoadedScene, frame: int) -> dict[str, Any]:
    """A finished frame's path and render seconds from its own header (frame_output.read_meta)."""
    from ..frame_output import read_meta
    from ..render.worker.job import frame_path

    path = frame_path(job, loaded, frame)
    try:
        meta = read_meta(path)
    except MotionError:
        return {}
    times = {k: float(meta[m]) for k, m in (("render_s", "render_seconds"), ("denoise_s", "denoise_seconds"))
             if isinstance(meta.get(m), (int, float)) and not isinstance(meta.get(m), bool)}
    return {"path": str(path), **times}


def build_report(
    *,
    loaded: LoadedScene,
    job: RenderJob,
    out_dir: Path,
    frames: list[int],
    selected: list[int],
    shard_spec: tuple[int, int] | None,
    skipped: list[int],
    sched: Scheduler | None,
    cfg: FarmConfig,
    executor_info: dict[str, Any],
    timings: dict[str, float],
    run_id: str,
    interrupted: bool,
    motion_file: str | None,
) -> dict[str, Any]:
    """The run's report (render-report.json): scene, selection, executor, timings, totals,
    per-frame and per-worker results, failures and frames not rendered."""
    rows = _frame_rows(skipped, sched, job, loaded)
    # interrupted frames are `not_rendered` (run.py settles them), never failed
    failed = [{"frame": r["frame"], "error": (r.get("errors") or ["not rendered"])[-1], "attempts": r.get("attempts", 0)} for r in rows if r["status"] in ("failed", "pending")]
    not_rendered = [r["frame"] for r in rows if r["status"] == "not_rendered"]
    return {
        "scene": str(loaded.path),
        "scene_name": loaded.name,
        "output_dir": str(out_dir),
        "run_id": run_id,
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "settings_hash": job.settings_hash,
        "scene_hash": job.scene_hash,
        "selection": format_frames(selected),
        "shard": f"{shard_spec[0]}/{shard_spec[1]}" if shard_spec else None,
        "frames_this_job": format_frames(frames),
        "motion_file": motion_file,
        "executor": executor_info,
        "config": {"retries": cfg.retries, "task_timeout_s": cfg.task_timeout_s, "max_worker_failures": cfg.max_worker_failures, "claim_stale_s": cfg.stale_after_s},
        "interrupted": interrupted,
        "disk_fault": sched.disk_fault if sched is not None else None,
        "totals": _totals(rows, len(frames), len(failed), timings),
        "failed": failed,
        "not_rendered": format_frames(not_rendered),
        "workers": _worker_rows(sched),
        "frames": rows,
    }


def _frame_rows(skipped: list[int], sched: Scheduler | None, job: RenderJob, loaded: LoadedScene) -> list[dict[str, Any]]:
    """One row per frame, in frame order: the frames kept (resume) and each frame the
    scheduler knew, with its status, attempts, errors and the worker's timings."""
    rows: list[dict[str, Any]] = []
    for f in skipped:
        rows.append({"frame": f, "status": "skipped", "reason": "complete on disk (resume)"})
    records = sched.frames if sched else {}
    for f, rec in sorted(records.items()):
        row: dict[str, Any] = {"frame": f, "status": rec.status, "attempts": rec.attempts, "retries": max(0, rec.attempts - 1)}
        r = rec.result
        if r is not None and r.ok:
            row.update(worker=r.worker, cold=r.cold, setup_s=r.setup_s, render_s=r.render_s, denoise_s=r.denoise_s, write_s=r.write_s, kernels_compiled=r.kernels_compiled, path=r.path, variant=r.variant, device=r.device)
        elif rec.status == "rendered":  # written before an interrupt, its chunk's result never came: its header has its time
            row.update(_times_on_disk(job, loaded, f))
        if rec.errors:
            row["errors"] = rec.errors
        rows.append(row)
    rows.sort(key=lambda r: r["frame"])
    return rows


def _worker_rows(sched: Scheduler | None) -> list[dict[str, Any]]:
    """One row per worker: frames, chunks, first and mean warm frame times, failures."""
    workers = []
    for w in (sched.workers.values() if sched else []):
        workers.append(
            {
                "worker": w.name,
                "frames": w.frames,
                "chunks": w.chunks,
                "first_frame_s": w.first_frame_s,
                "warm_render_mean_s": math.fsum(w.warm_render_s) / len(w.warm_render_s) if w.warm_render_s else None,  # (statistics.fmean's sum)
                "failures": w.failures,
                "excluded": w.excluded,
                "lost": w.lost,
            }
        )
    return workers


def _totals(rows: list[dict[str, Any]], frames: int, failed: int, timings: dict[str, float]) -> dict[str, Any]:
    """The report's totals: frames by final state (`failed` also counts the frames a disk
    fault stopped before they ran), retries, summed times, throughput."""
    by_state = {state: sum(1 for r in rows if r["status"] == state) for state in FINAL_FRAME_STATES}
    rendered = [r for r in rows if r["status"] == "rendered"]
    farm_s = timings.get("farm_s", 0.0)
    return {
        "frames": frames,
        **by_state,
        "failed": failed,
        "retries": sum(r.get("retries", 0) for r in rows),
        "cold_frames": sum(1 for r in rendered if r.get("cold")),
        "render_s_sum": sum(r.get("render_s", 0.0) for r in rendered),
        "setup_s_sum": sum(r.get("setup_s", 0.0) for r in rendered),
        "frames_per_minute": 60.0 * len(rendered) / farm_s if farm_s > 0 else 0.0,
        **timings,
    }


HISTORY_LIMIT = 100  # runs kept in a report's history


def merge_previous(report: dict[str, Any], path: str | Path, exists: Callable[[int], bool]) -> None:
    """Keep what the report at `path` knew of the folder: a rerun that renders nothing (or
    a few frames) must not lose the record of the frames already there. Skipped frames keep
    the row of the run that rendered them (`rendered_in_run`, worker, times); the earlier
    run joins `history` (newest last, at most HISTORY_LIMIT); `folder` lists every frame of
    the folder that a run of this report rendered and that is still on disk."""
    before = read_previous(path)
    if before.get("scene_name") != report.get("scene_name"):
        before = {}
    old_rows = {r.get("frame"): r for r in before.get("frames", []) if isinstance(r, dict)}
    for row in report["frames"]:
        prev = old_rows.get(row["frame"])
        if row["status"] == "skipped" and isinstance(prev, dict):
            if prev.get("status") == "rendered":
                row["rendered_in_run"] = before.get("run_id")
                row.update({k: prev[k] for k in ("worker", "render_s", "setup_s", "denoise_s", "path") if k in prev})
            elif "rendered_in_run" in prev:
                row.update({k: prev[k] for k in ("rendered_in_run", "worker", "render_s", "setup_s", "denoise_s", "path") if k in prev})
    for row in report["frames"]:
        if row["status"] == "rendered":
            row["rendered_in_run"] = report.get("run_id")
    history = [h for h in before.get("history", []) if isinstance(h, dict)]
    if before.get("run_id"):
        history.append({k: before.get(k) for k in ("run_id", "finished", "selection", "shard", "frames_this_job", "settings_hash", "totals")})
    report["history"] = history[-HISTORY_LIMIT:]
    known = set()
    folder = before.get("folder")
    if isinstance(folder, dict) and isinstance(folder.get("frames"), list):
        known |= {f for f in folder["frames"] if isinstance(f, int)}
    known |= {r["frame"] for r in report["frames"] if r["status"] in ("rendered", "skipped", "done_elsewhere")}
    frames = sorted(f for f in known if exists(f))
    report["folder"] = {"frames": frames, "complete": format_frames(frames), "count": len(frames)}


MAX_REPORT_BYTES = 64 * 1024**2  # a previous render-report.json read back (a million frames' rows are ~150 MB: their history is dropped)
_SCALAR = (str, int, float, type(None))
_ROW_FIELDS = {"frame": int, "status": str, "rendered_in_run": (str, type(None)), "worker": (str, type(None)), "render_s": (int, float, type(None)),
               "setup_s": (int, float, type(None)), "denoise_s": (int, float, type(None)), "path": (str, type(None))}


def read_previous(path: str | Path) -> dict[str, Any]:
    """The report a previous run left at `path`, or {} when there is none. One that cannot
    be trusted (not a regular file, over MAX_REPORT_BYTES, not JSON, nested past what the
    parser takes, or a field of the wrong type) is discarded with one warning line and the
    run writes a new one: it only carries history, and a damaged one stopped every later
    run with a traceback (a FIFO in its place hung it)."""
    import logging

    from ..errors import InputFileError
    from ..limits import read_bounded

    if not os.path.lexists(path):
        return {}
    try:
        before = json.loads(read_bounded(path, MAX_REPORT_BYTES, "previous report"))
        problem = _report_problem(before)
    except InputFileError as exc:
        problem = exc.reason
    except (ValueError, RecursionError) as exc:  # (UnicodeDecodeError is a ValueError)
        problem = f"not JSON ({type(exc).__name__}: {str(exc)[:80]})"
    if problem is None:
        return before
    logging.getLogger("motion").warning(f"motion: warning: {path}: {problem}; its history is discarded and a new report is written")
    return {}


def _report_problem(before: Any) -> str | None:
    """What makes a previous report untrustworthy (the fields merge_previous reads), or None."""
    if not isinstance(before, dict):
        return f"the report is a {type(before).__name__}, not an object"
    for key, kinds in (("scene_name", (str, type(None))), ("run_id", (str, type(None))), ("frames", list), ("history", list), ("folder", (dict, type(None)))):
        if not isinstance(before.get(key, None if key not in ("frames", "history") else []), kinds):  # type: ignore[arg-type]
            return f"'{key}' is a {type(before.get(key)).__name__}"
    for k, row in enumerate(before.get("frames", [])):
        if not isinstance(row, dict):
            return f"frames[{k}] is not an object"
        for field, kinds in _ROW_FIELDS.items():
            if field in row and (not isinstance(row[field], kinds) or isinstance(row[field], bool)):  # type: ignore[arg-type]
                return f"frames[{k}].{field} is a {type(row[field]).__name__}"
    for k, run in enumerate(before.get("history", [])):
        if not isinstance(run, dict):
            return f"history[{k}] is not an object"
        for field, value in run.items():
            flat = value.values() if isinstance(value, dict) else [value]
            if not all(isinstance(v, _SCALAR) for v in flat):
                return f"history[{k}].{str(field)[:40]} holds nested data"
    folder = before.get("folder") or {}
    if not isinstance(folder.get("frames", []), list):
        return "folder.frames is not a list"
    for key in ("finished", "selection", "shard", "frames_this_job", "settings_hash"):
        if not isinstance(before.get(key), _SCALAR):
            return f"'{key}' is a {type(before.get(key)).__name__}"
    totals = before.get("totals")
    if totals is not None and not (isinstance(totals, dict) and all(isinstance(v, _SCALAR) for v in totals.values())):
        return "'totals' is not a flat object"
    return None


def write_report(report: dict[str, Any], path: str | Path) -> Path:
    """Write atomically (a reader never sees half a report; a failed write leaves no
    temporary file). A disk fault raises DiskFaultError."""
    return write_atomic(path, (json.dumps(report, indent=2) + "\n").encode(), "writing the report")


def fallback_report_path(run_id: str) -> Path:
    """Where a report goes when its own place refuses it: the system's temporary folder."""
    return Path(tempfile.gettempdir()) / f"motion-render-report-{run_id}.json"


def write_report_somewhere(report: dict[str, Any], path: str | Path, run_id: str) -> tuple[Path | None, str | None]:
    """Write the report at `path`, or, if that disk refuses it, in the temporary folder.
    Returns (where it went or None, the disk fault at `path` or None)."""
    try:
        return write_report(report, path), None
    except DiskFaultError as exc:
        fault = str(exc)
    report = {**report, "report_fault": fault}
    try:
        return write_report(report, fallback_report_path(run_id)), fault
    except (DiskFaultError, OSError):
        return None, fault


def check_writable(folder: str | Path, what: str) -> None:
    """Before any work: `folder` exists or can be made, and a file can be created in it.
    UsageError (exit 2) naming the folder and the reason otherwise."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{what} {folder}: cannot write there: it is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".motion-probe.", suffix=".tmp", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        fault = disk_fault(exc, "creating a file in", folder)
        reason = str(fault) if fault is not None else f"{exc.strerror or exc}"
        raise UsageError(f"{what} {folder}: cannot write there: {reason}") from None
