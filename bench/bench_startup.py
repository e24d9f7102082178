"""Small jobs at the engine's start-up cost (issue 28): whole processes, as CI runs them.

    python bench/bench_startup.py               # 5 alternating rounds, warm kernel cache, then an empty one
    python bench/bench_startup.py --rounds 3 --no-cold
    python bench/bench_startup.py --only validate   # validate of every example, warm and with an empty cache root
    python bench/bench_startup.py --only rerun --rounds 3   # reruns that render nothing, beside validate

Jobs (each a fresh process, alternating, medians, with the CPU named):
- the ci-smoke job of every example (`motion -q render SCENE --preset ci-smoke`), and the
  same job of bouncing-balls against the plain-Mitsuba script of its frames
  (bench/plain/bouncing_balls_smoke.py: import mitsuba, load_dict, render x3, write EXR);
- a one-frame preview render of bouncing-balls;
- `motion validate` of every example, `--dry-run` of bouncing-balls, `motion --help`;
- a rerun of the ci-smoke job of the simulated examples that renders nothing (`--resume`
  over its own frames), and of the whole 48-frame wrecking shot at its own settings,
  beside their validate (every frame's identity kept: identity/kept.py, no bake);
- with a Python that has `bpy` (`--cycles-python PY` or $BENCH_CYCLES_PYTHON; skipped
  otherwise): one frame of the bench shot of bench_equal_error.py (100k-triangle terrain,
  4 moving balls, sky + sun, 320x180, 16 spp, 180-degree shutter) in a fresh process, ours
  (`motion -q render`) against Blender Cycles' (`bpy`, built from Python by
  bench_equal_error's worker, CPU, 2 threads).
With an empty kernel cache (a fresh DRJIT_CACHE_DIR and MOTION_CACHE_DIR for each run) the
smoke job is measured again, with and without `motion cache warm` first.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
MOTION = str(BIN / "motion")
EXAMPLES = sorted(p.stem for p in (ROOT / "scenes").glob("*.yaml"))
# simulated shots whose rerun reads the kept simulation: two examples and the kind of shot issue 46 wrote
RERUN = {**{n: ROOT / "scenes" / f"{n}.yaml" for n in ("bouncing-balls", "cannonball-splash")}, "wrecking": ROOT / "bench" / "shots" / "wrecking.yaml"}


def timed(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of one process (its children included)."""
    t0 = time.perf_counter()
    proc = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    rss_kb = float(proc.stderr.strip().splitlines()[-1])
    return wall, rss_kb / 1024


def main() -> None:
    """Measure and print the table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-cold", action="store_true", help="skip the empty-kernel-cache runs")
    ap.add_argument("--only", help="only the jobs whose name contains this text (e.g. validate)")
    ap.add_argument("--cycles-python", default=os.environ.get("BENCH_CYCLES_PYTHON"), help="a Python with bpy: also time Cycles' one frame of the bench shot")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-startup-"))
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as an installed motion runs: from its modules' cached bytecode, not compiled every process
    jobs: dict[str, list[str]] = {
        "plain mitsuba: bouncing-balls 3 frames": [sys.executable, str(ROOT / "bench" / "plain" / "bouncing_balls_smoke.py"), str(tmp / "plain")],
    }
    for name in EXAMPLES:
        jobs[f"ci-smoke {name}"] = [MOTION, "-q", "render", str(ROOT / "scenes" / f"{name}.yaml"), "--preset", "ci-smoke", "-o", str(tmp / f"smoke-{name}"), "--overwrite"]
    jobs["one preview frame bouncing-balls"] = [MOTION, "-q", "render", str(ROOT / "scenes" / "bouncing-balls.yaml"), "--preset", "preview", "--frames", "10",
                                                "-o", str(tmp / "one"), "--overwrite"]
    for name in EXAMPLES:
        jobs[f"validate {name}"] = [MOTION, "validate", str(ROOT / "scenes" / f"{name}.yaml")]
    for name, path in RERUN.items():  # the untimed pass renders the frames; every timed run renders nothing (the kept simulation, bake/keep.py)
        jobs[f"rerun ci-smoke {name}, renders nothing"] = [MOTION, "-q", "render", str(path), "--preset", "ci-smoke", "-o", str(tmp / f"rerun-{name}"), "--resume"]
        jobs.setdefault(f"validate {name}", [MOTION, "validate", str(path)])
    # the whole 48-frame shot at the scene's own settings: every frame's identity known without a bake (identity/kept.py)
    jobs["rerun full wrecking, renders nothing"] = [MOTION, "-q", "render", str(RERUN["wrecking"]), "-o", str(tmp / "rerun-full-wrecking"), "--resume"]
    jobs["--dry-run bouncing-balls"] = [MOTION, "-q", "render", str(ROOT / "scenes" / "bouncing-balls.yaml"), "--dry-run", "-o", str(tmp / "dry")]
    jobs["--help"] = [MOTION, "--help"]
    if args.only:
        beside = {f"validate {n}" for n in RERUN} if "rerun" in args.only else set()  # a rerun is read beside its validate
        jobs = {k: v for k, v in jobs.items() if args.only in k or k.startswith("plain") or k in beside}
    if args.cycles_python:
        import json

        from bench_equal_error import FRAME, bench_shot, cycles_spec

        (tmp / "shot").mkdir()
        path = bench_shot(tmp / "shot", denoise=False)
        spec = tmp / "shot" / "spec.json"
        spec.write_text(json.dumps({**cycles_spec(path), "one": 16}))
        jobs["one bench-shot frame, ours (16 spp)"] = [MOTION, "-q", "render", str(path), "--frames", str(FRAME), "-o", str(tmp / "shot-ours"), "--overwrite"]
        jobs["one bench-shot frame, Cycles (16 spp)"] = [args.cycles_python, str(ROOT / "bench" / "bench_equal_error.py"), "--cycles-worker", str(spec)]
    for cmd in jobs.values():  # once, untimed: kernels compiled, files cached
        timed(cmd, env)
    times: dict[str, list[float]] = {k: [] for k in jobs}
    rss: dict[str, list[float]] = {k: [] for k in jobs}
    for _ in range(args.rounds):
        for name, cmd in jobs.items():
            w, m = timed(cmd, env)
            times[name].append(w)
            rss[name].append(m)
    print(f"# small jobs, whole processes, median of {args.rounds} alternating rounds, warm kernel cache ({cpu_model()})")
    anchor = statistics.median(times["plain mitsuba: bouncing-balls 3 frames"])
    for name in jobs:
        med = statistics.median(times[name])
        ratio = f"  {med / anchor:5.2f}x plain" if name.startswith("ci-smoke bouncing-balls") or name.startswith("plain") else ""
        if name == "one bench-shot frame, ours (16 spp)":
            ratio = f"  {med / statistics.median(times['one bench-shot frame, Cycles (16 spp)']):5.2f}x Cycles"
        scene = name.split()[2].rstrip(",") if name.startswith(("rerun ci-smoke ", "rerun full ")) else ""
        if scene and f"validate {scene}" in times:
            ratio = f"  {med / statistics.median(times['validate ' + scene]):5.2f}x validate"
        print(f"{name:42} {med:7.3f} s  {statistics.median(rss[name]):6.0f} MB{ratio}")
    if not args.only or "validate" in args.only:
        # what validation keeps (the scene's compiled validator, the assets whose bytes
        # passed, a glTF import's records: docs/ci-sharding.md) is lost with the cache root
        print("# validate with an empty cache root (a fresh MOTION_CACHE_DIR each run: the first validate on a machine)")
        for name in ("bouncing-balls", "cannonball-splash", "walker-meadow"):
            walls = [timed([MOTION, "validate", str(ROOT / "scenes" / f"{name}.yaml")], {**env, "MOTION_CACHE_DIR": str(tmp / f"vcache-{name}-{r}")})[0] for r in range(args.rounds)]
            print(f"{'validate ' + name + ', empty cache root':52} {statistics.median(walls):7.3f} s")
    if args.no_cold or args.only:
        return
    print("# empty kernel cache (fresh MOTION_CACHE_DIR and DRJIT_CACHE_DIR each run)")
    smoke = jobs["ci-smoke bouncing-balls"]
    for label, warm_first in (("ci-smoke bouncing-balls, empty cache", False), ("ci-smoke bouncing-balls after `motion cache warm`", True)):
        walls = []
        for r in range(max(1, args.rounds // 2)):
            cold = {**env, "MOTION_CACHE_DIR": str(tmp / f"cache-{label[:8]}-{r}{warm_first}"), "DRJIT_CACHE_DIR": str(tmp / f"cache-{label[:8]}-{r}{warm_first}" / "kernels")}
            if warm_first:
                timed([MOTION, "-q", "cache", "warm", str(ROOT / "scenes" / "bouncing-balls.yaml"), "--preset", "ci-smoke"], cold)
            walls.append(timed(smoke, cold)[0])
        print(f"{label:52} {statistics.median(walls):7.3f} s")


if __name__ == "__main__":
    main()
