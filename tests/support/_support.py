"""Shared test helpers (importable as `_support`): run the real `motion` command."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "scenes"
MOTION = str(Path(sys.executable).with_name("motion"))


def run_motion(*args: str, env: dict[str, str] | None = None, timeout: float = 300, cwd: str | Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run `motion ARGS...` in a subprocess as a user would; returns the completed process."""
    full_env = dict(os.environ)
    if env:
        full_env.update(env)
    return subprocess.run([MOTION, *args], capture_output=True, text=True, timeout=timeout, env=full_env, cwd=cwd or REPO)


def assert_card_upright(tmp_path: Path, asset: str) -> None:
    """Render the imported `asset` (a card textured red above blue, facing +Z) through
    `motion render` and check that red is at the top of the frame and blue at the bottom."""
    from motion.pipeline.frame_output import read_frame

    (tmp_path / "card.yaml").write_text(
        f"camera: {{position: [0, 0, 4], look_at: [0, 0, 0], fov: 40}}\nimports: [{{file: {asset}}}]\n"
        "lights: [{type: constant, radiance: 1}]\nrender: {resolution: [16, 16], spp: 2}\n"
    )
    proc = run_motion("render", str(tmp_path / "card.yaml"), "-o", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    rgb = read_frame(next((tmp_path / "out").glob("card.*.exr"))).rgba[..., :3]
    top, bottom = rgb[5, 8], rgb[11, 8]
    assert top[0] > 5 * top[2] and bottom[2] > 5 * bottom[0], (top, bottom)
