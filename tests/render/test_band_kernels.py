"""Frames in bands reuse their kernels: a band's first row, its row count and its place in
the frame are read by the kernels at run time (render/kernel/film.py `_opaque`), so every band of
a frame, and every pass of a band, replays the kernels of the first; a frame of 48 bands
traces about as many kernels as the same frame in one band (it traced 485 against 16, and
took 22 s against 0.8 s)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import load, render

pytestmark = pytest.mark.render

SCENE = """
camera: {{position: [0, 0.4, 4], look_at: [0, 0, 0], fov: 40}}
timeline: {{fps: 24, first: 0, last: 0}}
render: {{resolution: [4, 48], spp: {spp}, max_depth: 2, filter: gaussian}}
lights: [{{type: constant, radiance: 0.5}}]
materials: [{{name: white, type: diffuse, color: 0.8}}]
objects:
  - {{name: ball, shape: sphere, radius: 1.0, material: white}}
"""


def _kernels(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, lanes: int | None, spp: int) -> tuple[set[str], int, np.ndarray]:
    if lanes is None:
        monkeypatch.delenv("MOTION_MAX_LANES", raising=False)
    else:
        monkeypatch.setenv("MOTION_MAX_LANES", str(lanes))
    (img,), _, renderer = render(load(tmp_path, SCENE.format(spp=spp)), [0])
    if not renderer.vectorized:
        pytest.skip("the scalar fallback traces no kernels")
    launched = renderer.last_kernels
    return {str(k["hash"]) for k in launched}, len(launched), np.asarray(img)


@pytest.mark.parametrize("spp", [1, 2])  # 2: two passes a band (4 took 20 s of a loaded suite run)
def test_a_frame_in_48_bands_traces_the_kernels_of_one_band(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, spp: int) -> None:
    whole, _, _ = _kernels(tmp_path, monkeypatch, None, spp)
    banded, launches, img = _kernels(tmp_path, monkeypatch, 1, spp)  # one pixel a pass: 48 bands of one row (and its filter's reach)
    assert launches >= 48 * len(whole) // 2  # it did render band by band
    assert len(banded) <= len(whole) + 2, (len(banded), len(whole))  # before: 485 kernels against 16
    assert img.shape == (48, 4, 4) and np.isfinite(img).all()
