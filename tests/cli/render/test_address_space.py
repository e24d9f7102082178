"""A frame whose render pass cannot fit the process's address space is refused before the bake."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

from _scenes import TWO_FRAMES as BASE


def _under_2_gib() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, resource.RLIM_INFINITY))


def test_a_frame_whose_pass_cannot_fit_the_address_space_is_refused_before_the_bake(tmp_path: Path) -> None:
    from farm_util import MOTION

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("[16, 12]", "[4096, 4096]"))
    t0 = time.monotonic()
    res = subprocess.run([MOTION, "render", str(scene), "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, preexec_fn=_under_2_gib)
    assert res.returncode == 2 and "s.yaml:4:" in res.stderr and "render.resolution: 4096x4096 needs about 2.3 GB for a worker (8388608 sample lanes a pass" in res.stderr, res.stderr
    assert time.monotonic() - t0 < 30 and not (tmp_path / "out").exists()  # before: std::bad_alloc on 3 attempts after the bake, exit 3
    scene.write_text(BASE.replace("[16, 12]", "[64, 48]"))  # a frame that fits renders under the same limit
    res = subprocess.run([MOTION, "render", str(scene), "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, preexec_fn=_under_2_gib)
    assert res.returncode == 0, res.stderr
