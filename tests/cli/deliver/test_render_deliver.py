"""`motion render ... --deliver` assembles the deliverables after the last frame."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import pytest

from motion.pipeline.frame_output import read_frame
from _support import SCENES, run_motion

pytestmark = pytest.mark.render


def test_render_then_deliver_24p_60i_and_contact_sheet(tmp_path: Path) -> None:
    import av

    out = tmp_path / "out"
    proc = run_motion(
        "render", str(SCENES / "walk-cycle.yaml"), "--preset", "ci-smoke", "--frames", "0-7",
        "--resolution", "32x24", "--deliver", "24p,60i,contact", "--deliver-frames", "0-7", "-o", str(out),
    )
    assert proc.returncode == 0, proc.stderr
    deliver = out / "deliver"
    with av.open(str(deliver / "walk-cycle_24p_0-7_v001.mov")) as movie:
        stream = movie.streams.video[0]
        frames = list(movie.decode(stream))
        assert len(frames) == 8
        assert stream.average_rate == Fraction(24000, 1001)  # film speed 23.976 by default
    # 8 film frames -> 10 interlaced video frames by 3:2 pulldown
    fields = sorted((deliver / "60i_0-7_v001").glob("*.exr"))
    assert len(fields) == 10
    assert read_frame(fields[0]).header["framesPerSecond"] == Fraction(30000, 1001)
    with av.open(str(deliver / "walk-cycle_60i_0-7_v001.mov")) as movie:
        frames = list(movie.decode(movie.streams.video[0]))
        assert len(frames) == 10 and frames[0].interlaced_frame
    assert (deliver / "walk-cycle_contact_0-7_v001.png").stat().st_size > 0


def test_deliver_refuses_shards(tmp_path: Path) -> None:
    proc = run_motion("render", str(SCENES / "walk-cycle.yaml"), "--shard", "1/2", "--deliver", "24p", "-o", str(tmp_path))
    assert proc.returncode == 2 and "--deliver needs every frame" in proc.stderr


def test_unknown_deliverable_fails_before_rendering(tmp_path: Path) -> None:
    proc = run_motion("render", str(SCENES / "walk-cycle.yaml"), "--deliver", "24p,4k", "-o", str(tmp_path))
    assert proc.returncode == 2 and "4k" in proc.stderr
    assert not list(tmp_path.glob("*.exr"))  # nothing was rendered


def test_deliver_through_an_ocio_view(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = run_motion(
        "render", str(SCENES / "walk-cycle.yaml"), "--preset", "ci-smoke", "--frames", "0-1", "--resolution", "32x24",
        "--deliver", "contact", "--ocio", "ocio://cg-config-latest", "--ocio-view", "Un-tone-mapped", "-o", str(out),
    )
    assert proc.returncode == 0, proc.stderr
    assert (out / "deliver" / "walk-cycle_contact_v001.png").is_file()
    bad = run_motion("render", str(SCENES / "walk-cycle.yaml"), "--preset", "ci-smoke", "--frames", "0-1", "--resolution", "32x24",
                     "--deliver", "contact", "--ocio", "ocio://cg-config-latest", "--ocio-view", "No Such View", "-o", str(tmp_path / "o2"))
    assert bad.returncode == 2 and "No Such View" in bad.stderr and "Traceback" not in bad.stderr


# `motion render` in a Python where `import av` fails (a farm node or container built without PyAV)
_WITHOUT_PYAV = """
import importlib.abc, sys
class _NoAv(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] == "av":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, _NoAv())
sys.argv[0] = "motion"
from motion.cli import start
start()
"""


def test_movies_without_pyav_are_one_line_before_any_frame(tmp_path: Path) -> None:
    """Without PyAV a movie deliverable is refused in one line naming the package, before any
    frame renders (it was an ImportError traceback); the contact sheet needs no PyAV."""
    import subprocess
    import sys

    args = ["render", str(SCENES / "cannonball.yaml"), "--frames", "0-2", "--resolution", "16x8", "--spp", "1", "--ocio", "none"]
    proc = subprocess.run([sys.executable, "-c", _WITHOUT_PYAV, *args, "-o", str(tmp_path / "a"), "--deliver", "24p,contact"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert "--deliver 24p: movies need PyAV (pip install av)" in proc.stderr and "Traceback" not in proc.stderr
    assert not list((tmp_path / "a").glob("*.exr"))
    proc = subprocess.run([sys.executable, "-c", _WITHOUT_PYAV, *args, "-o", str(tmp_path / "b"), "--deliver", "contact"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert list((tmp_path / "b" / "deliver").glob("*contact*.png"))
    # the scene's own output.deliver (24p, 60i, contact): made without its movies, each said why
    proc = subprocess.run([sys.executable, "-c", _WITHOUT_PYAV, "render", str(SCENES / "cannonball-splash.yaml"), "--frames", "0-71x12", "--resolution", "16x8",
                           "--spp", "1", "--ocio", "none", "--no-denoise", "-o", str(tmp_path / "c")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "movies need PyAV" in proc.stderr + proc.stdout and "Traceback" not in proc.stderr
