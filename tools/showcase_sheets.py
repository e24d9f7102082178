"""Contact sheets of every example scene for docs/showcase/, made by the pipeline itself.

    python tools/showcase_sheets.py [SCENE.yaml ...]      # default: every scenes/*.yaml

For each scene: `motion render` of FRAMES frames spread evenly over its timeline at
RESOLUTION (the scene's own samples, denoiser and lights), into out/showcase-sheets/<name>/,
then `motion contact-sheet` of them into docs/showcase/<name>.png (thumbnails WIDTH pixels
wide, COLUMNS to a row). The sheet of the `make render` shot can instead be made from that
run's full frames: `motion contact-sheet out/cannonball-splash -o ... --max-frames 8`.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MOTION = str(Path(sys.executable).with_name("motion"))
FRAMES = 8
RESOLUTION = "320x180"
WIDTH = 200
COLUMNS = 4


def spread(first: int, last: int, count: int = FRAMES) -> list[int]:
    """`count` frame numbers spread evenly over [first, last], both ends included."""
    if last - first + 1 <= count:
        return list(range(first, last + 1))
    return sorted({first + round(i * (last - first) / (count - 1)) for i in range(count)})


def sheet(scene: Path, work: Path, docs: Path) -> Path:
    """Render a few frames of `scene` and write its contact sheet; returns the sheet's path."""
    info = json.loads(subprocess.run([MOTION, "validate", "--json", str(scene)], check=True,
                                     capture_output=True, text=True).stdout)
    first, last = info["scenes"][0]["frames"]
    name = info["scenes"][0]["name"]
    frames = ",".join(str(f) for f in spread(first, last))
    out = work / name
    subprocess.run([MOTION, "render", str(scene), "-o", str(out), "--frames", frames,
                    "--resolution", RESOLUTION, "--no-progress"], check=True)
    target = docs / f"{name}.png"
    subprocess.run([MOTION, "contact-sheet", str(out), "-o", str(target), "--width", str(WIDTH),
                    "--columns", str(COLUMNS), "--prefix", name], check=True)
    return target


def main(argv: list[str]) -> int:
    """Make the sheets of the scenes named (default: all examples); print each path."""
    scenes = [Path(a) for a in argv[1:]] or sorted((ROOT / "scenes").glob("*.yaml"))
    docs = ROOT / "docs" / "showcase"
    docs.mkdir(parents=True, exist_ok=True)
    for scene in scenes:
        path = sheet(scene, ROOT / "out" / "showcase-sheets", docs)
        print(f"{path.relative_to(ROOT)}  ({path.stat().st_size // 1024} KB)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
