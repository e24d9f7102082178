"""Benchmark: the farm on this machine.

  throughput  frames per minute on the same 24-frame preview shot (spinning-top,
              --preset preview: 320x180, 16 spp, depth 4) with 1 and 2 local workers and a
              2-worker Dask cluster on loopback (one drjit thread per worker when 2).
              Wall time includes worker start-up; "farm" time is from first task to last.
  overhead    scheduling cost per task: a 1x1-pixel, 1-spp render, one frame per task,
              minus the time the workers spent rendering and writing.
  memory      peak RSS of the main process and of each worker over a 200-frame job
              (tiny resolution), sampled through the job: the last quarter's peak against
              the second quarter's (after start-up) (flat, not growing with frame count).
  scale       tasks per second the client sustains with 8 and 16 Dask workers on loopback
              (one 8x6-px 1-spp frame a task of the farm test scene with a 768 KiB
              texture on its floor, workers warmed by a first job), each Dask job twice:
              shared disk (`--transfer shared`: workers read the scene, write the frames)
              and no shared disk (`--transfer ship`: the parsed scene and the texture
              travel, the frames come home); bytes per frame from Dask's own counter
              (scheduler to workers: tasks with their arguments) and from the report's
              `executor.transfer` (the client's pickled task arguments, the EXR bytes
              home, the texture bytes handed to workers in the warm-up job: the fan-out),
              the client's peak RSS; beside it the same job on two local workers.
  client      the main process's RSS for a 100,000-frame job: when planned (first frame on
              disk) and its growth per finished frame over 20 s, then Ctrl-C
              (`client_memory` says why that is the whole cost); with two local workers,
              and on a 2-worker Dask cluster with a shared disk and shipped (the client
              then also claims and publishes the frames).

    python bench/bench_farm.py [--frames 24] [--memory-frames 200] [--only scale --only client]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
MOTION = str(BIN / "motion")
SHOT = ROOT / "scenes" / "spinning-top.yaml"
TINY = ROOT / "tests" / "data" / "farm-tiny.yaml"


def render(args: list[str], out: Path, sample_memory: bool = False) -> tuple[dict, float, dict]:
    """Run `motion render`; returns (report, wall seconds, samples: RSS in MB of the main
    process and of each local worker, and the main process's CPU seconds as `main_cpu_s`,
    every 50 ms while `sample_memory`)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([MOTION, "render", *args, "-o", str(out), "--no-progress", "--overwrite"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    samples: dict[str, list[tuple[float, float]]] = {}
    if sample_memory:
        main = psutil.Process(proc.pid)
        while proc.poll() is None:
            try:
                now = time.perf_counter() - t0
                procs = [("main", main)] + [(f"worker:{c.pid}", c) for c in main.children(recursive=True) if "spawn_main" in " ".join(c.cmdline()) and "resource_tracker" not in " ".join(c.cmdline())]
                for name, p in procs:
                    samples.setdefault(name, []).append((now, p.memory_info().rss / 2**20))
                cpu = main.cpu_times()
                samples.setdefault("main_cpu_s", []).append((now, cpu.user + cpu.system))
            except psutil.Error:
                pass
            time.sleep(0.05)
    _, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"render failed ({proc.returncode}):\n{err}")
    report = json.loads((out / "render-report.json").read_text())
    return report, wall, samples


class Cluster:
    """A `dask scheduler` and N single-threaded `dask worker`s on 127.0.0.1; with `caches`,
    each worker has its own cache folder under it (as if on a machine of its own: a shipped
    asset then crosses once to each)."""

    def __init__(self, workers: int, caches: Path | None = None) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{port}"
        dask = str(BIN / "dask")
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        self.procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet)]
        for i in range(workers):
            env = {**os.environ, "MOTION_CACHE_DIR": str(caches / f"worker-{i}")} if caches else None
            self.procs.append(subprocess.Popen([dask, "worker", self.address, "--nthreads", "1", "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"], env=env, **quiet))
        from distributed import Client

        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(self.address, timeout=5) as c:
                    c.wait_for_workers(workers, timeout=30)
                break
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

    def close(self) -> None:
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:  # a worker still inside a task's kernel: not a result
                p.kill()
                p.wait()


def throughput(frames: int, tmp: Path) -> dict[str, dict]:
    common = [str(SHOT), "--preset", "preview", "--frames", f"0-{frames - 1}"]
    out: dict[str, dict] = {}
    for name, extra in (("local x1", ["--workers", "1"]), ("local x2", ["--workers", "2"])):
        rep, wall, _ = render(common + extra, tmp / name.replace(" ", ""))
        out[name] = {"wall_s": wall, "farm_s": rep["totals"]["farm_s"], "first_frame_s": [w["first_frame_s"] for w in rep["workers"]], "warm_render_s": [w["warm_render_mean_s"] for w in rep["workers"]]}
    cluster = Cluster(2)
    try:
        rep, wall, _ = render(common + ["--scheduler", cluster.address, "--threads", "1"], tmp / "dask")
        out["dask x2"] = {"wall_s": wall, "farm_s": rep["totals"]["farm_s"], "first_frame_s": [w["first_frame_s"] for w in rep["workers"]], "warm_render_s": [w["warm_render_mean_s"] for w in rep["workers"]]}
        # a second job on the same cluster: workers are already warm
        rep, wall, _ = render(common + ["--scheduler", cluster.address, "--threads", "1"], tmp / "dask")
        out["dask x2 (warm cluster)"] = {"wall_s": wall, "farm_s": rep["totals"]["farm_s"], "first_frame_s": [w["first_frame_s"] for w in rep["workers"]], "warm_render_s": [w["warm_render_mean_s"] for w in rep["workers"]]}
        out["_overhead_dask"] = overhead(["--scheduler", cluster.address, "--threads", "1"], tmp / "ovd")
    finally:
        cluster.close()
    for v in out.values():
        if "wall_s" in v:
            v["fpm_wall"] = 60 * frames / v["wall_s"]
            v["fpm_farm"] = 60 * frames / v["farm_s"]
    return out


def long_scene(tmp: Path, frames: int) -> Path:
    """The tiny test scene with a timeline of `frames` frames."""
    text = TINY.read_text().replace("last: 47", f"last: {frames - 1}")
    path = tmp / "farm-long.yaml"
    path.write_text(text.replace("name: farm-tiny", "name: farm-long"))
    return path


def overhead(extra: list[str], out: Path, frames: int = 120) -> dict[str, float]:
    rep, wall, _ = render([str(long_scene(out.parent, frames)), "--frames", f"0-{frames - 1}", "--resolution", "1x1", "--spp", "1", "--chunk-size", "1", *extra], out)
    work = sum(r.get("setup_s", 0) + r.get("render_s", 0) + r.get("write_s", 0) for r in rep["frames"])
    tasks = rep["executor"]["chunks"]
    workers = max(1, len(rep["workers"]))
    # farm time x workers = busy + idle; what is not rendering/writing is scheduling
    per_task = (rep["totals"]["farm_s"] * workers - work) / tasks
    return {"tasks": tasks, "farm_s": rep["totals"]["farm_s"], "work_s": work, "per_task_ms": 1000 * per_task / workers, "per_task_worker_ms": 1000 * per_task}


def memory(frames: int, tmp: Path) -> dict[str, dict]:
    rep, wall, samples = render([str(long_scene(tmp, frames)), "--frames", f"0-{frames - 1}", "--resolution", "32x24", "--spp", "1", "--workers", "2"], tmp / "mem", sample_memory=True)
    out = {}
    for name, series in samples.items():
        if len(series) < 4:
            continue
        t0, t_end = series[0][0], series[-1][0]
        quarter = lambda k: [m for t, m in series if t0 + (k - 1) * (t_end - t0) / 4 < t <= t0 + k * (t_end - t0) / 4 + 1e-9]  # noqa: E731
        q2, q4 = max(quarter(2) or [0.0]), max(quarter(4) or [0.0])
        out[name] = {"peak_mb": max(m for _, m in series), "q2_peak_mb": q2, "q4_peak_mb": q4, "growth": q4 / q2 if q2 else float("nan"), "samples": len(series)}
    return out


def _to_workers_bytes(address: str) -> int:
    """Dask's own byte counter of what the scheduler has sent its workers over their
    streams: the tasks with their arguments, and control messages. (Results are not
    counted here: the workers' `transfer_outgoing_bytes_total` adds Dask's `sizeof`
    estimate of each result, 56 bytes for any small object, not the bytes on the wire.)"""
    from distributed import Client

    with Client(address, timeout=10) as c:
        return int(c.run_on_scheduler(lambda dask_scheduler: sum(b.byte_count for b in dask_scheduler.stream_comms.values())))


def _cpu_s(pid: int) -> float:
    times = psutil.Process(pid).cpu_times()
    return times.user + times.system


def textured_scene(tmp: Path, frames: int) -> Path:
    """`long_scene` with a 512x512 noise texture (768 KiB, incompressible) on its floor: an
    asset for ship mode to carry."""
    import numpy as np
    from PIL import Image

    Image.fromarray(np.random.default_rng(1).integers(0, 256, (512, 512, 3), dtype=np.uint8)).save(tmp / "floor.png")
    path = long_scene(tmp, frames)
    path.write_text(path.read_text().replace("{name: floor, type: diffuse, color: 0.5}", "{name: floor, type: diffuse, color: {file: floor.png}}"))
    return path


def scale(worker_counts: list[int], frames: int, tmp: Path) -> dict[str, dict]:
    """Tasks per second the client sustains with many Dask workers on loopback: tiny frames
    (8x6 px, 1 spp, one frame a task), after a first job on the same cluster has paid every
    worker's first-frame costs (and, shipped, filled its asset cache); the bytes sent to
    workers per frame (Dask's own counter) and the report's transfer figures; the CPU the
    client and the scheduler spend per task, from a job of a quarter of the frames and the
    full job (the difference, so start-up and the bake drop out); the client's peak RSS.
    Each cluster runs the job with a shared disk and shipped, the same frames. Beside it,
    the same job on two local worker processes."""
    scene = textured_scene(tmp, frames)
    small = max(1, frames // 4)
    job = lambda n: [str(scene), "--frames", f"0-{n - 1}", "--resolution", "8x6", "--spp", "1", "--chunk-size", "1"]  # noqa: E731
    out: dict[str, dict] = {}
    rep, wall, samples = render(job(frames) + ["--workers", "2"], tmp / "scale-local", sample_memory=True)
    out["local x2"] = {"tasks": rep["executor"]["chunks"], "farm_s": rep["totals"]["farm_s"], "wall_s": wall, "client_peak_mb": max(m for _, m in samples.get("main", [(0, 0.0)]))}
    for n in worker_counts:
        cluster = Cluster(n, caches=tmp / f"caches-{n}")
        try:
            for mode in ("shared", "ship"):
                dask = ["--scheduler", cluster.address, "--threads", "1", "--transfer", mode]
                warm, _, _ = render(job(frames) + dask, tmp / f"scale-warm-{n}-{mode}")  # every worker's first frame, outside the measured jobs
                sched_pid = cluster.procs[0].pid
                c0 = _cpu_s(sched_pid)
                _, _, few = render(job(small) + dask, tmp / f"scale-few-{n}-{mode}", sample_memory=True)
                c1, sent0 = _cpu_s(sched_pid), _to_workers_bytes(cluster.address)
                rep, wall, samples = render(job(frames) + dask, tmp / f"scale-dask-{n}-{mode}", sample_memory=True)
                c2, sent1 = _cpu_s(sched_pid), _to_workers_bytes(cluster.address)
                client_few, client_all = few["main_cpu_s"][-1][1], samples["main_cpu_s"][-1][1]
                moved = rep["executor"].get("transfer", {})
                out[f"dask x{n} {mode}"] = {"tasks": rep["executor"]["chunks"], "farm_s": rep["totals"]["farm_s"], "wall_s": wall,
                                            "client_peak_mb": max(m for _, m in samples.get("main", [(0, 0.0)])),
                                            "to_workers_per_frame": (sent1 - sent0) / frames,
                                            "task_args_per_frame": moved.get("task_bytes", 0) / frames,
                                            "home_per_frame": moved.get("frame_bytes_home", 0) / frames,
                                            "fan_out_bytes": warm["executor"].get("transfer", {}).get("asset_bytes_to_workers", 0),
                                            "asset_bytes": moved.get("asset_bytes", 0),
                                            "client_ms_per_task": 1000 * (client_all - client_few) / (frames - small),
                                            "scheduler_ms_per_task": 1000 * ((c2 - c1) - (c1 - c0)) / (frames - small)}
        finally:
            cluster.close()
    for v in out.values():
        v["tasks_per_s"] = v["tasks"] / v["farm_s"]
    return out


def _sigint_default() -> None:
    """In the child, before exec: SIGINT as a terminal gives it (a bench started in the
    background inherits it ignored, and the Ctrl-C that ends the job would be lost)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def client_memory(frames: int, seconds: float, tmp: Path, executor: list[str] | None = None) -> dict[str, float]:
    """The main process's RSS over a job of `frames` frames (the farm test scene, 1x1 px,
    1 spp, two local workers; the client's share is the same with Dask): when planning is
    done (the first frame is on disk: bake, frame paths, resume checks, chunks and the
    scheduler's records all exist), and its growth per finished frame over the next
    `seconds`, after which the job is interrupted (Ctrl-C) and the report read for how many
    frames were done. Rendering all of them is not needed: nothing per frame is allocated
    later except a finished frame's record, whose cost is the growth measured here.
    `executor`: other flags than `--workers 2` (a Dask cluster, a transfer mode)."""
    scene = long_scene(tmp, frames)
    out = tmp / ("client-memory" + "-".join(executor or []).replace("/", "").replace(":", ""))
    cmd = [MOTION, "render", str(scene), "--frames", f"0-{frames - 1}", "--resolution", "1x1", "--spp", "1", *(executor or ["--workers", "2"]), "-o", str(out), "--no-progress", "--overwrite"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_default)
    main = psutil.Process(proc.pid)
    peak, planned, planned_at, series = 0.0, None, None, []
    while proc.poll() is None:
        try:
            rss = main.memory_info().rss / 2**20
        except psutil.Error:
            break
        now = time.perf_counter() - t0
        peak = max(peak, rss)
        series.append((now, rss))
        if planned is None and out.is_dir() and any(out.glob("*.exr")):
            planned, planned_at = peak, now
        if planned_at is not None and now - planned_at > seconds:
            proc.send_signal(signal.SIGINT)
            break
        time.sleep(0.05)
    _, err = proc.communicate()
    if planned is None:
        raise SystemExit(f"client memory: no frame was written ({proc.returncode}):\n{err}")
    rep = json.loads((out / "render-report.json").read_text())
    done = rep["totals"]["rendered"]
    end = max(m for t, m in series if t >= series[-1][0] - 1.0)
    growth = max(0.0, end - planned) / max(1, done)
    return {"frames": frames, "planned_mb": planned, "planned_s": planned_at, "done": done, "end_mb": end, "peak_mb": peak,
            "per_frame_kb": 1024 * growth, "extrapolated_mb": planned + growth * frames}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--memory-frames", type=int, default=200)
    ap.add_argument("--scale-workers", default="8,16", help="Dask worker counts for the scale section")
    ap.add_argument("--scale-frames", type=int, default=400)
    ap.add_argument("--client-frames", type=int, default=100_000)
    ap.add_argument("--client-seconds", type=float, default=20.0)
    ap.add_argument("--only", choices=["throughput", "memory", "scale", "client"], action="append", help="run only these sections (repeatable)")
    args = ap.parse_args()
    only = set(args.only or ["throughput", "memory", "scale", "client"])
    with tempfile.TemporaryDirectory(prefix="bench-farm-") as d:
        tmp = Path(d)
        print(f"cpu: {cpu_model()}, {len(os.sched_getaffinity(0))} cores")
        if "throughput" in only:
            tp = throughput(args.frames, tmp)
            base = tp["local x1"]
            print(f"\nthroughput: {SHOT.name} --preset preview, {args.frames} frames")
            print(f"{'executor':24} {'wall s':>7} {'fr/min':>7} {'farm s':>7} {'fr/min':>7} {'vs x1':>6}  first-frame s / warm render s per worker")
            for name, v in tp.items():
                if name.startswith("_"):
                    continue
                ff = ", ".join(f"{a:.2f}/{b:.3f}" for a, b in zip(v["first_frame_s"], v["warm_render_s"]) if a is not None and b is not None)
                print(f"{name:24} {v['wall_s']:7.2f} {v['fpm_wall']:7.1f} {v['farm_s']:7.2f} {v['fpm_farm']:7.1f} {v['fpm_wall'] / base['fpm_wall']:6.2f}  {ff}")
            ov_local = overhead(["--workers", "1"], tmp / "ovl")
            ov_dask = tp["_overhead_dask"]
            print("\nscheduling overhead per task (1x1 px, 1 spp, one frame per task):")
            for name, ov in (("local x1", ov_local), ("dask x2", ov_dask)):
                print(f"  {name:10} {ov['tasks']} tasks in {ov['farm_s']:.2f}s (worker busy {ov['work_s']:.2f}s): {ov['per_task_worker_ms']:.1f} ms per task per worker")
        if "memory" in only:
            mem = memory(args.memory_frames, tmp)
            print(f"\nmemory over a {args.memory_frames}-frame job (32x24, 2 local workers): peak RSS, MB")
            for name, m in mem.items():
                print(f"  {name:16} peak {m['peak_mb']:7.1f}  2nd quarter {m['q2_peak_mb']:7.1f}  last quarter {m['q4_peak_mb']:7.1f}  growth x{m['growth']:.3f}")
        if "scale" in only:
            counts = [int(n) for n in args.scale_workers.split(",") if n]
            sc = scale(counts, args.scale_frames, tmp)
            print(f"\nscale: {args.scale_frames} tasks of one 8x6-px 1-spp frame (warm workers), a 768 KiB texture; bytes per frame")
            print(f"{'executor':16} {'tasks/s':>8} {'farm s':>7} {'client MB':>10} {'to workers':>11} {'task args':>10} {'home':>7} {'client ms/task':>15} {'scheduler ms/task':>18} {'fan-out MiB':>12}")
            for name, v in sc.items():
                cols = [f"{v[k]:{w}.{d}f}" if k in v else f"{'-':>{w}}" for k, w, d in (("to_workers_per_frame", 11, 0), ("task_args_per_frame", 10, 0), ("home_per_frame", 7, 0), ("client_ms_per_task", 15, 2), ("scheduler_ms_per_task", 18, 2))]
                fan = f"{v['fan_out_bytes'] / 2**20:12.2f}" if "fan_out_bytes" in v else f"{'-':>12}"
                print(f"{name:16} {v['tasks_per_s']:8.1f} {v['farm_s']:7.2f} {v['client_peak_mb']:10.1f} " + " ".join(cols) + " " + fan)
        if "client" in only:
            cluster = Cluster(2)
            try:
                dask = ["--scheduler", cluster.address, "--threads", "1", "--transfer"]
                runs = (("2 local workers", None), ("shared disk, 2 Dask workers", [*dask, "shared"]), ("shipped, 2 Dask workers", [*dask, "ship"]))
                for name, executor in runs:
                    cm = client_memory(args.client_frames, args.client_seconds, tmp, executor)
                    print(f"\nclient memory, a {cm['frames']}-frame job, {name}: {cm['planned_mb']:.0f} MB when planned ({cm['planned_s']:.1f} s), "
                          f"{cm['end_mb']:.0f} MB after {cm['done']} frames ({cm['per_frame_kb']:.2f} KB per finished frame), "
                          f"{cm['extrapolated_mb']:.0f} MB extrapolated to the last frame")
            finally:
                cluster.close()

if __name__ == "__main__":
    main()
