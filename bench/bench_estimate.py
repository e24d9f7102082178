"""How close `motion render --dry-run`'s estimate, and the live ETA once 10% of the frames
are done, come to the real time of the job (issue 23: within 1.5x on the examples).

    python bench/bench_estimate.py                       # 3 examples, preview, 24 frames each
    python bench/bench_estimate.py --scenes walk-cycle --frames 0-47 --preset preview

For each scene: the dry run's estimate, the real run's wall time (whole process), the ratio;
then the ETA printed by the first progress line at or past 10% of the frames against the
time the job really had left then. Runs twice per scene with a fresh estimate history
(`MOTION_CACHE_DIR`'s estimates.json removed): the first estimate comes from the built-in
figures or the other scenes measured before it, the second from the scene's own first run.
With `--fresh` the compiled kernels start empty too (a new machine, a fresh clone: the first
run compiles every kernel; issue 38 measured 10.4 s estimated for a 99.8 s first run);
without it they are shared with the user's cache, and the first run is not a compile test.

    python bench/bench_estimate.py --fresh --scenes spinning-top --frames 0-11
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MOTION = str(Path(sys.executable).with_name("motion"))
PROGRESS = re.compile(r"^\s+\S+: (\d+)/(\d+) frames, .* ETA (\d+)s")


def run(scene: str, out: Path, frames: str, preset: str) -> dict[str, float | None]:
    """One scene: the dry run's estimate, the real wall time, the ETA at 10% and the truth then."""
    base = [MOTION, "render", str(ROOT / "scenes" / f"{scene}.yaml"), "-o", str(out), "--frames", frames, "--preset", preset]
    dry = subprocess.run([*base, "--dry-run", "--json"], capture_output=True, text=True, check=True)
    estimate = json.loads(dry.stdout)["estimate"]
    t0 = time.monotonic()
    proc = subprocess.Popen(base, stderr=subprocess.PIPE, text=True)
    eta_at = None
    assert proc.stderr is not None
    for line in proc.stderr:
        m = PROGRESS.match(line)
        if m and eta_at is None:
            done, total, eta = int(m[1]), int(m[2]), int(m[3])
            if done >= max(1, total // 10):
                eta_at = (time.monotonic() - t0, float(eta))
    proc.wait()
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{scene}: motion render exited {proc.returncode}")
    out_eta = {"eta_s": eta_at[1], "left_s": wall - eta_at[0]} if eta_at else {"eta_s": None, "left_s": None}
    return {"estimate_s": float(estimate["seconds"]), "basis": estimate["basis"], "wall_s": wall, **out_eta}


def main() -> None:
    """Run the comparison and print one table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default="bouncing-balls,spinning-top,walk-cycle")
    ap.add_argument("--frames", default="0-23")
    ap.add_argument("--preset", default="preview")
    ap.add_argument("--fresh", action="store_true", help="start with no compiled kernels either (a new machine)")
    args = ap.parse_args()
    print(f"# estimate vs real time ({cpu_model()}), preset {args.preset}, frames {args.frames}{', fresh kernel cache' if args.fresh else ''}")
    print(f"{'scene':16} {'run':5} {'estimate':>9} {'real':>8} {'ratio':>6} {'ETA@10%':>8} {'left':>7} {'ratio':>6}  basis")
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        os.environ["MOTION_CACHE_DIR"] = str(cache)
        # share compiled kernels with the user's cache, so the first run is not a compile benchmark
        if args.fresh:
            os.environ["DRJIT_CACHE_DIR"] = str(cache / "kernels")
        else:
            os.environ.setdefault("DRJIT_CACHE_DIR", str(Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "motion" / "kernels"))
        for scene in args.scenes.split(","):
            for attempt in (1, 2):
                r = run(scene, Path(tmp) / f"{scene}-{attempt}", args.frames, args.preset)
                ratio = max(r["estimate_s"], r["wall_s"]) / max(1e-9, min(r["estimate_s"], r["wall_s"]))  # type: ignore[type-var]
                if r["eta_s"] is not None and r["left_s"]:
                    eta_ratio = max(r["eta_s"], r["left_s"]) / max(1e-9, min(r["eta_s"], r["left_s"]))  # type: ignore[type-var]
                    eta_txt = f"{r['eta_s']:8.1f} {r['left_s']:7.1f} {eta_ratio:6.2f}"
                else:
                    eta_txt = f"{'-':>8} {'-':>7} {'-':>6}"
                print(f"{scene:16} {attempt:5d} {r['estimate_s']:9.1f} {r['wall_s']:8.1f} {ratio:6.2f} {eta_txt}  {r['basis']}", flush=True)


if __name__ == "__main__":
    main()
