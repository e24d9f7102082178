"""Deliverable assembly beside the render: frames/s per format (issue 38).

    python bench/bench_deliver.py [--scene scenes/cannonball-splash.yaml] [--spp 1]
                                  [--frames-dir DIR] [--formats 24p,60i,contact]
                                  [--repeat 2] [--compare OTHER/.venv/bin/python]

Renders the scene once (its own resolution, `--spp` samples; or takes the frames already in
`--frames-dir`, rendered with the same `--spp`, linked into a folder of the benchmark's own), then times two things per format, best of
`--repeat`, wall and CPU seconds, each in a fresh process:

- command: `motion render SCENE -o FRAMES --spp N --check --deliver FMT` (what a CI gather
  job runs: the check of every frame, then the deliverable), with no earlier version of it
  (the deliver folder removed first);
- assembly: the telecine stage's `deliver()` alone (read, view transform, pulldown,
  encode), into a fresh folder.

With `--compare PYTHON` (another checkout's interpreter, e.g. the main branch's
`.venv/bin/python`; its `motion` is the one beside it) the same runs are made with that
checkout's code, alternating with this one's, so both see the same host load. Figures:
film frames per second of wall time, beside the render's frames per second; the CPU model
and core count are printed with them.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
from _common import cpu_model  # noqa: E402

MOTION = str(Path(sys.executable).with_name("motion"))

# run by each interpreter: time deliver() of one format, print wall and CPU seconds as JSON
TIMER = """
import json, resource, sys, time
from motion.pipeline.telecine.deliver import deliver
from motion.pipeline.telecine.movie import ViewTransform
frames, out, fmt = sys.argv[1:4]
view = ViewTransform()
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
t0, c0 = time.perf_counter(), cpu()
deliver(frames, out, (fmt,), view=view)
print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": cpu() - c0}))
"""


def assemble(python: str, frames: Path, fmt: str, work: Path) -> dict[str, float]:
    """One timed assembly of `fmt` by `python`'s checkout, into a fresh folder."""
    out = Path(tempfile.mkdtemp(prefix=f"{fmt}-", dir=work))
    proc = subprocess.run([python, "-c", TIMER, str(frames), str(out), fmt], capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{python}: deliver {fmt} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def command(python: str, scene: str, frames: Path, spp: int, fmt: str) -> dict[str, float]:
    """One timed `motion render --check --deliver fmt` by `python`'s checkout (its deliver
    folder removed first, so the deliverable is made, not found up to date)."""
    shutil.rmtree(frames / "deliver", ignore_errors=True)
    motion = str(Path(python).with_name("motion"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([motion, "render", scene, "-o", str(frames), "--spp", str(spp), "--check", "--deliver", fmt, "--no-progress"],
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{motion}: --check --deliver {fmt} failed:\n{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu}


def main() -> None:
    """Render once (or take --frames-dir), then time each format's assembly per checkout."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=str(REPO / "scenes" / "cannonball-splash.yaml"))
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--frames-dir", type=Path, help="frames already rendered (skips the render)")
    ap.add_argument("--formats", default="24p,60i,contact")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--compare", help="another checkout's python to time side by side (e.g. main's .venv/bin/python)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args()
    pythons = {"this checkout": sys.executable, **({"compared": args.compare} if args.compare else {})}
    with tempfile.TemporaryDirectory(prefix="bench-deliver-") as tmp:
        work = Path(tmp)
        render: dict[str, float] = {}
        frames = work / "frames"
        if args.frames_dir is not None:  # linked into a folder of ours: its deliver/ is removed before each command
            frames.mkdir()
            for p in args.frames_dir.glob("*.exr"):
                try:
                    os.link(p, frames / p.name)
                except OSError:  # another file system
                    shutil.copy2(p, frames / p.name)
        else:
            t0 = time.perf_counter()
            subprocess.run([MOTION, "render", args.scene, "-o", str(frames), "--spp", str(args.spp), "--deliver", "none", "--no-progress"],
                           check=True, capture_output=True)
            render["wall_s"] = time.perf_counter() - t0
            totals = json.loads((frames / "render-report.json").read_text())["totals"]
            render["render_s_sum"] = totals.get("render_s_sum", 0.0)
        n = len(list(frames.glob("*.exr")))
        timers = {"command": lambda py, fmt: command(py, args.scene, frames, args.spp, fmt),
                  "assembly": lambda py, fmt: assemble(py, frames, fmt, work)}
        best: dict[str, dict[str, dict[str, dict[str, float]]]] = {kind: {label: {} for label in pythons} for kind in timers}
        for fmt in args.formats.split(","):
            for _ in range(args.repeat):
                for label, python in pythons.items():  # alternating: both see the same load
                    for kind, timer in timers.items():
                        t = timer(python, fmt)
                        if fmt not in best[kind][label] or t["wall_s"] < best[kind][label][fmt]["wall_s"]:
                            best[kind][label][fmt] = t
    figures = {"cpu": cpu_model(), "cores": len(os.sched_getaffinity(0)), "scene": args.scene, "frames": n, "spp": args.spp,
               "render": render, **best}
    if args.json:
        print(json.dumps(figures, indent=2))
        return
    print(f"{figures['cpu']} ({figures['cores']} cores), load {os.getloadavg()[0]:.1f}; {n} frames of {Path(args.scene).name}, spp {args.spp}")
    if render:
        print(f"  render: {render['wall_s']:.1f} s whole command ({n / render['wall_s']:.2f} frames/s), "
              f"{render['render_s_sum']:.1f} s in the renderer ({n / max(render['render_s_sum'], 1e-9):.2f} frames/s)")
    for kind, what in (("command", "motion render --check --deliver FMT"), ("assembly", "deliver() alone")):
        print(f"  {what}:")
        for fmt in args.formats.split(","):
            line = "  ".join(f"{label}: {n / r[fmt]['wall_s']:6.1f} frames/s ({r[fmt]['wall_s']:.1f} s wall, {r[fmt]['cpu_s']:.1f} s CPU)"
                             for label, r in best[kind].items())
            print(f"    {fmt:8s} {line}")


if __name__ == "__main__":
    main()
