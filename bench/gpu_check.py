"""Issue 35 on a GPU machine, in one device call: every example rendered on CUDA and on LLVM,
counting disabled ray-tracing operations and comparing the frames region by region.

    python bench/gpu_check.py --out DIR [--preset ci-smoke] [--scenes a.yaml,b.yaml] [--showcase]

For each example of scenes/ at the preset (default ci-smoke, its 3 frames): `motion render
--variant cuda_ad_rgb`, then the same frames with `--variant llvm_ad_rgb`. Per example:
the exit codes, drjit's "Disabling this ray tracing operation" lines on stderr (the target
is 0: a frame with one fails, docs/rendering.md), the report's variant and device of each
frame, the CUDA and LLVM seconds; per frame: the RGB means of a 4x4 grid of regions and a
z-score for each (the difference over the standard error of both region means, the pixel
spread standing for the noise: a generous bound, since it holds the image's structure
too). A frame is flagged where a region differs by more than 5% of the frame's mean and
|z| > 4: a missing mover shows as both. `--showcase` also renders cannonball-splash's whole
timeline on CUDA (frames per minute). Writes DIR/gpu-check.json and prints a table; exits
1 if any trace was disabled, a render failed or a frame is flagged.

`--reference DIR` reads the reference frames from DIR/<example>/ instead of rendering them
(a device machine without libLLVM: render them first on a CPU with `--make-reference DIR`,
which renders only the reference variant).

On the device machine (../shared/gpu/README.md): `bash .gpu/run.sh bash tools/gpu_device.sh`,
with carry [".gpu"] (the kit, and the references in .gpu/refs).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DISABLED = "Disabling this ray tracing operation"
GRID = 4


def motion_command() -> list[str]:
    """The `motion` launcher: beside python3 (the device kit's run.sh puts it there), on
    PATH, else this interpreter running the CLI."""
    beside = Path(sys.executable).with_name("motion")
    if beside.exists():
        return [str(beside)]
    found = shutil.which("motion")
    return [found] if found else [sys.executable, "-c", "import sys; sys.argv[0] = 'motion'; from motion.cli import start; start()"]


def render(scene: Path, variant: str, out: Path, preset: str, extra: list[str] | None = None) -> dict[str, Any]:
    """One `motion render` of `scene` with `variant` into `out`: exit code, seconds,
    disabled traces on stderr, the report's frames, the error lines."""
    t0 = time.perf_counter()
    proc = subprocess.run([*motion_command(), "render", str(scene), "--preset", preset, "--variant", variant, "-o", str(out), "--overwrite", "--no-progress", *(extra or [])],
                          capture_output=True, text=True, timeout=900)
    seconds = time.perf_counter() - t0
    report = out / "render-report.json"
    frames = json.loads(report.read_text())["frames"] if report.exists() else []
    return {
        "variant": variant,
        "code": proc.returncode,
        "seconds": round(seconds, 2),
        "disabled_traces": proc.stderr.count(DISABLED),
        "frames": [{k: f.get(k) for k in ("frame", "status", "variant", "device", "render_s", "cold")} for f in frames],
        "errors": [line for line in proc.stderr.splitlines() if line.startswith("error:")][:5],
    }


def regions(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per region of a GRID x GRID split: the mean RGB [G, G, 3], the pixel variance [G, G, 3]
    and the pixel count [G, G]."""
    h, w = rgb.shape[:2]
    ys, xs = np.linspace(0, h, GRID + 1).astype(int), np.linspace(0, w, GRID + 1).astype(int)
    mean, var, count = np.zeros((GRID, GRID, 3)), np.zeros((GRID, GRID, 3)), np.zeros((GRID, GRID))
    for i in range(GRID):
        for j in range(GRID):
            block = rgb[ys[i] : ys[i + 1], xs[j] : xs[j + 1]].reshape(-1, 3).astype(np.float64)
            mean[i, j], var[i, j], count[i, j] = block.mean(0), block.var(0), len(block)
    return mean, var, count


def compare(cuda: np.ndarray, llvm: np.ndarray) -> dict[str, float | bool]:
    """Region means of two renders of one frame: the largest |z| and relative difference,
    and whether they disagree beyond noise (both bounds exceeded in one region)."""
    ma, va, n = regions(cuda[..., :3])
    mb, vb, _ = regions(llvm[..., :3])
    se = np.sqrt((va + vb) / np.maximum(n, 1)[..., None]) + 1e-12
    z = np.abs(ma - mb) / se
    scale = max(float(llvm[..., :3].mean()), 1e-6)
    rel = np.abs(ma - mb) / scale
    return {"max_z": round(float(z.max()), 2), "max_rel": round(float(rel.max()), 4), "flagged": bool(((z > 4) & (rel > 0.05)).any())}


def main() -> int:
    """Run the check; print and write the figures."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--preset", default="ci-smoke")
    parser.add_argument("--scenes", help="comma-separated example files (default: every scenes/*.yaml)")
    parser.add_argument("--showcase", action="store_true", help="also cannonball-splash's whole timeline on CUDA (frames per minute)")
    parser.add_argument("--variants", default="cuda_ad_rgb,llvm_ad_rgb", help="the variant checked and its reference (llvm_ad_rgb,llvm_ad_rgb tries the script on a CPU)")
    parser.add_argument("--reference", type=Path, help="read the reference frames from DIR/<example>/ instead of rendering them")
    parser.add_argument("--render-args", default="", help="more `motion render` options for every render, e.g. '--no-denoise --deliver none' where mitsuba-oidn or PyAV is absent")
    parser.add_argument("--make-reference", type=Path, help="only render the reference variant's frames into DIR/<example>/, then stop")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from motion.pipeline.frame_output import read_frame

    checked, reference = args.variants.split(",")
    extra = args.render_args.split()
    names = args.scenes.split(",") if args.scenes else sorted(p.name for p in (ROOT / "scenes").glob("*.yaml"))
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"], capture_output=True, text=True).stdout.strip() if shutil.which("nvidia-smi") else "no nvidia-smi"
    results: dict[str, Any] = {"gpu": gpu, "preset": args.preset, "cores": os.cpu_count(), "scenes": {}}
    bad = False
    print(f"# gpu_check: {gpu}; preset {args.preset}")
    print("| scene | cuda exit | disabled traces | cuda s | llvm exit | llvm s | frames | max z | max rel | flagged | device |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    if args.make_reference:
        for name in names:
            made = render(ROOT / "scenes" / name, reference, args.make_reference / name.rsplit(".", 1)[0], args.preset, extra)
            print(f"reference {name}: exit {made['code']}, {made['seconds']} s", *made["errors"], sep="\n    ")
        return 0
    for name in names:
        scene = ROOT / "scenes" / name
        stem = name.rsplit(".", 1)[0]
        cuda = render(scene, checked, args.out / "cuda" / stem, args.preset, extra)
        if args.reference:
            llvm = {"variant": reference, "code": 0 if (args.reference / stem).is_dir() else 1, "seconds": 0.0, "disabled_traces": 0, "frames": [], "errors": []}
            ref_dir = args.reference / stem
        else:
            llvm = render(scene, reference, args.out / "llvm" / stem, args.preset, extra)
            ref_dir = args.out / "llvm" / stem
        frames = []
        for exr in sorted((args.out / "cuda" / stem).glob("*.exr")):
            other = ref_dir / exr.name
            if other.exists():
                frames.append({"file": exr.name, **compare(read_frame(exr).rgba, read_frame(other).rgba)})
        entry = {"cuda": cuda, "llvm": llvm, "frames": frames}
        results["scenes"][name] = entry
        flagged = sum(f["flagged"] for f in frames)
        bad |= cuda["code"] != 0 or llvm["code"] != 0 or cuda["disabled_traces"] > 0 or flagged > 0 or not frames
        devices = sorted({str(f.get("device")) for f in cuda["frames"]})
        print(f"| {name} | {cuda['code']} | {cuda['disabled_traces']} | {cuda['seconds']} | {llvm['code']} | {llvm['seconds']} | {len(frames)} | "
              f"{max((f['max_z'] for f in frames), default=float('nan'))} | {max((f['max_rel'] for f in frames), default=float('nan'))} | {flagged} | {','.join(devices)} |")
        for line in cuda["errors"] + llvm["errors"]:
            print(f"    {line}")
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "gpu-check.json").write_text(json.dumps(results, indent=1))  # so far: a timeout keeps it
    if args.showcase:
        show = render(ROOT / "scenes" / "cannonball-splash.yaml", checked, args.out / "showcase", "preview", ["--frames", "0-71", *extra])
        rendered = sum(1 for f in show["frames"] if f["status"] == "rendered")
        show["frames_per_minute"] = round(60 * rendered / max(show["seconds"], 1e-9), 1)
        results["showcase"] = {k: v for k, v in show.items() if k != "frames"}
        bad |= show["code"] != 0 or show["disabled_traces"] > 0
        print(f"\nshowcase cannonball-splash 0-71 (preview) on CUDA: exit {show['code']}, {show['seconds']} s, {show['frames_per_minute']} frames/min, {show['disabled_traces']} disabled traces")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "gpu-check.json").write_text(json.dumps(results, indent=1))
    print(f"\n{'FAILED' if bad else 'ok'}: figures in {args.out / 'gpu-check.json'}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
