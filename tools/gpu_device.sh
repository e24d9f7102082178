#!/usr/bin/env bash
# Issue 35's figures on a lent GPU machine, in one device call (docs/rendering.md, "On the GPU").
#
# Here, first:   bash ../shared/gpu/prepare.sh
#                .venv/bin/python bench/gpu_check.py --out /tmp/gc --make-reference .gpu/refs \
#                    --render-args "--no-denoise --deliver none --ocio none --spp 32 --resolution 128x72"   (RENDER_ARGS below)
# Then one device call with carry [".gpu"]:   bash .gpu/run.sh bash tools/gpu_device.sh
# Any other command on the device: bash .gpu/run.sh bash tools/gpu_device.sh -- python3 -m pytest ...
# (the kit's run.sh links pyproject's package-dir, which this project does not have: setup.py
# maps the folders, and this script links them as it does, then runs the command instead).
#
# Steps, each under its own time limit so that a slow one leaves the others their figures,
# everything written under $OUT: the machine; every example at ci-smoke on cuda_ad_rgb against
# the LLVM references made here (bench/gpu_check.py: disabled traces, region z-scores); the
# showcase's whole timeline at preview on CUDA (frames per minute, from its render report);
# the render benchmark against Mitsuba's `path` on CUDA; the rendering tests on CUDA.
set -uo pipefail
out=${OUT:-/tmp/gpu-out}; mkdir -p "$out"
site=${GPU_SITE:-/tmp/site}

# The kit's run.sh links packages from pyproject's package-dir; ours are mapped by setup.py's
# ROOTS (motion.cli -> cli, ...): link those, as an editable install would see them.
python3 - "$site" <<'PY' || exit 1
import ast, os, sys
site = sys.argv[1]
tree = ast.parse(open("setup.py").read())
roots = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign) and getattr(n.targets[0], "id", "") == "ROOTS")
for pkg, folder in roots.items():
    dst = os.path.join(site, *pkg.split("."))
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    if os.path.lexists(dst):
        os.unlink(dst)
    os.symlink(os.path.abspath(folder), dst)
print("linked:", ", ".join(f"{k} -> {v}" for k, v in roots.items()))
PY
if [ "${1:-}" = "--" ]; then shift; exec "$@"; fi

{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; lscpu | grep 'Model name'; nproc
  ldconfig -p | grep -i 'libLLVM' || echo "no libLLVM"; python3 --version; } > "$out/machine.txt" 2>&1
cat "$out/machine.txt"

step() {  # step NAME SECONDS COMMAND...: run with a limit, log to $OUT/NAME.log, say how it ended
  local name=$1 limit=$2; shift 2
  local t0=$SECONDS
  timeout -k 5 "$limit" "$@" > "$out/$name.log" 2>&1
  local rc=$?
  echo "== $name: exit $rc in $((SECONDS - t0)) s (limit $limit s)"
  tail -n 25 "$out/$name.log"
}

# The kit has neither mitsuba-oidn nor PyAV: no denoiser, no movies; more samples than ci-smoke
# so that a region's z-score can see a wrong object, not only a missing one.
RENDER_ARGS="--no-denoise --deliver none --ocio none --spp 32 --resolution 128x72"
step check 200 python3 bench/gpu_check.py --out "$out/check" --reference .gpu/refs --render-args "$RENDER_ARGS"
step showcase 90 motion render scenes/cannonball-splash.yaml --preset preview --frames 0-71 --variant cuda_ad_rgb -o /tmp/showcase --no-progress --overwrite --no-denoise --deliver none --ocio none
cp /tmp/showcase/render-report.json "$out/showcase-report.json" 2>/dev/null
python3 - "$out/showcase-report.json" <<'PY' 2>&1 | tee -a "$out/showcase.log"
import json, sys, statistics
r = json.load(open(sys.argv[1]))
fr = [f for f in r["frames"] if f.get("status") == "rendered"]
warm = [f["render_s"] for f in fr if not f.get("cold")]
print(f"showcase: {len(fr)} rendered; variants {sorted({f.get('variant') for f in fr})}; devices {sorted({str(f.get('device')) for f in fr})}; "
      f"warm render_s median {statistics.median(warm):.3f} s over {len(warm)}; report keys {sorted(k for k in r if k != 'frames')}")
PY
step bench 110 python3 bench/bench_vs_mitsuba.py --quick --frames 3 --json "$out/bench_vs_mitsuba.json"
step tests 150 python3 -m pytest -q -p no:cacheprovider -o addopts= --durations=8 \
  tests/render/test_correctness.py tests/render/test_blur.py tests/render/test_nonrigid.py tests/render/test_sbt.py \
  tests/render/test_updates.py tests/render/test_culling.py tests/cli/examples/test_smoke.py
