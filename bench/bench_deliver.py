"""Deliverable assembly beside the render: frames/s per format (issue 38).

    python bench/bench_deliver.py [--scene scenes/cannonball-splash.yaml] [--spp 1]
                                  [--formats 24p,60i,contact] [--repeat 2]
                                  [--motion PATH ...]

Renders the scene once (its own resolution, `--spp` samples) into a scratch folder, then
for each `motion` command given (default: this checkout's; pass another checkout's
`.venv/bin/motion` as a second `--motion` to compare before/after side by side in one run)
times, in a fresh copy of the frames each time:

  check            `motion render SCENE --check` (load, bake, every frame checked)
  check + FORMAT   `motion render SCENE --check --deliver FORMAT`

and reports the assembly of each format as (check + FORMAT) - check seconds and as film
frames per second, the best of `--repeat` runs, beside the render's own frames/s. The
frames are the same real EXRs for every command; the CPU model is printed with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
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


def timed(cmd: list[str], env: dict[str, str]) -> float:
    """Wall seconds of a command that must succeed."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return seconds


def fresh_copy(frames: Path, work: Path) -> Path:
    """The rendered frames (and their report) in a new folder with no deliverables."""
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    for p in frames.iterdir():
        if p.is_file() and (p.suffix == ".exr" or p.name == "render-report.json"):
            os.link(p, work / p.name)
    return work


def main() -> None:
    """Render once, then time --check and --check --deliver FORMAT per motion command."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=str(REPO / "scenes" / "cannonball-splash.yaml"))
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--formats", default="24p,60i,contact")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--motion", action="append", help="a motion command to time (repeatable; default: this checkout's)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args()
    commands = args.motion or [MOTION]
    env = {**os.environ, "MOTION_PROGRESS": "0"}
    with tempfile.TemporaryDirectory(prefix="bench-deliver-") as tmp:
        frames = Path(tmp) / "frames"
        t0 = time.perf_counter()
        subprocess.run([MOTION, "render", args.scene, "-o", str(frames), "--spp", str(args.spp), "--deliver", "none", "--no-progress"],
                       check=True, capture_output=True, env=env)
        render_s = time.perf_counter() - t0
        n = len(list(frames.glob("*.exr")))
        results: dict[str, dict[str, float]] = {}
        for cmd in commands:
            base = [cmd, "render", args.scene, "--spp", str(args.spp), "--no-progress", "--check"]
            row: dict[str, float] = {}
            check = min(timed(base + ["-o", str(fresh_copy(frames, Path(tmp) / "w"))], env) for _ in range(args.repeat))
            row["check_s"] = check
            for fmt in args.formats.split(","):
                whole = min(timed(base + ["-o", str(fresh_copy(frames, Path(tmp) / "w")), "--deliver", fmt], env) for _ in range(args.repeat))
                row[f"{fmt}_s"] = whole
                row[f"{fmt}_assembly_s"] = max(whole - check, 1e-9)
                row[f"{fmt}_frames_per_s"] = n / max(whole - check, 1e-9)
            results[cmd] = row
    figures = {"cpu": cpu_model(), "cores": len(os.sched_getaffinity(0)), "scene": args.scene, "frames": n, "spp": args.spp,
               "render_s": render_s, "render_frames_per_s": n / render_s, "commands": results}
    if args.json:
        print(json.dumps(figures, indent=2))
        return
    print(f"{figures['cpu']} ({figures['cores']} cores); {Path(args.scene).name}: {n} frames at spp {args.spp}")
    print(f"  render (cold, whole command): {render_s:.1f} s, {n / render_s:.2f} frames/s")
    for cmd, row in results.items():
        print(f"  {cmd}: --check {row['check_s']:.1f} s")
        for fmt in args.formats.split(","):
            print(f"    {fmt:8s} --check --deliver {row[f'{fmt}_s']:6.1f} s; assembly {row[f'{fmt}_assembly_s']:5.1f} s = {row[f'{fmt}_frames_per_s']:6.1f} frames/s")


if __name__ == "__main__":
    main()
