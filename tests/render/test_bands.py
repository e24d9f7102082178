"""A frame of more pixels than the lane budget ($MOTION_MAX_LANES) renders in bands of rows
(render/kernel/film.py: `bands`), each with the filter's reach of rows above and below, so no pass
holds more lanes than the budget; a frame that fits is one band, as it always was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import load, render

pytestmark = pytest.mark.render

SCENE = """
camera: {{position: [0, 0.4, 4], look_at: [0, 0, 0], fov: 40}}
timeline: {{fps: 24, first: 0, last: 0}}
render: {{resolution: [{w}, {h}], spp: {spp}, max_depth: 2, filter: gaussian}}
lights: [{{type: constant, radiance: 0.5}}]
materials: [{{name: white, type: diffuse, color: 0.8}}]
objects:
{objects}
"""
BALL = "  - {name: ball, shape: sphere, radius: 1.0, material: white}"


@pytest.mark.parametrize("rows,width,apron,budget", [(24, 32, 1, 32 * 6), (24, 32, 2, 32 * 24), (100, 7, 1, 7 * 9), (5, 10, 3, 10)])
def test_bands_deliver_every_row_once_and_render_each_ones_reach(rows: int, width: int, apron: int, budget: int) -> None:
    from motion.pipeline.render.kernel.film import bands

    got = bands(rows, width, apron, budget)
    delivered = [r for first, last, _, _ in got for r in range(first, last)]
    assert delivered == list(range(rows))
    for first, last, lo, hi in got:
        assert lo == max(0, first - apron) and hi == min(rows, last + apron)
        if budget >= width * (1 + 2 * apron):
            assert (hi - lo) * width <= budget
    assert (len(got) == 1) == (rows * width <= budget)


def _frame(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, budget: int | None, objects: str, spp: int, size: tuple[int, int] = (32, 24)) -> np.ndarray:
    if budget is None:
        monkeypatch.delenv("MOTION_MAX_LANES", raising=False)
    else:
        monkeypatch.setenv("MOTION_MAX_LANES", str(budget))
    loaded = load(tmp_path, SCENE.format(w=size[0], h=size[1], spp=spp, objects=objects))
    (img,), _, _ = render(loaded, [0])
    return np.asarray(img)


def test_a_banded_frame_has_every_row_and_its_whole_filter(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The sky alone is 0.5 at every sample: a banded frame (budget 5 rows a pass, so 8 bands
    and their seams) is 0.5 at every pixel, as the one-band frame is - a row left out, delivered
    twice or filtered with another band's weights shows."""
    whole = _frame(tmp_path, monkeypatch, None, "  []", 4)
    banded = _frame(tmp_path, monkeypatch, 32 * 5, "  []", 4)
    assert whole.shape == banded.shape == (24, 32, 4)
    np.testing.assert_allclose(banded[..., :3], 0.5, atol=1e-6)
    np.testing.assert_allclose(banded, whole, atol=1e-6)


def test_a_banded_frame_agrees_with_the_whole_one_row_by_row(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A lit ball: each row's mean in the banded frame agrees with the one-band frame's within
    the noise of 32 samples a pixel (a band shifted by a row moves the ball's rim: far off).
    At 7 rows of 32 pixels a pass, each pass is one sample of a band: 32 samples keep the
    passes to some 160 (256 took 200 s of a loaded suite run, in 1,300 tiny launches).
    (A frame that fits is one band, bit for bit as before: tools/frame_digest.py.)"""
    whole = _frame(tmp_path, monkeypatch, None, BALL, 32)
    banded = _frame(tmp_path, monkeypatch, 32 * 7, BALL, 32)
    assert whole[12, 16, :3].mean() > 0.3 and abs(whole[1, 1, :3].mean() - 0.5) < 1e-6  # the ball in the middle, the sky in the corner
    rows_whole, rows_banded = whole[..., :3].mean(axis=(1, 2)), banded[..., :3].mean(axis=(1, 2))
    # the rows differ by 0.0008 at most; the frame shifted by one row differs by 0.018
    assert np.abs(rows_banded - rows_whole).max() < 0.005, np.abs(rows_banded - rows_whole)
    assert not np.array_equal(banded, whole)  # other bands drew other samples
