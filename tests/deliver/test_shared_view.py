"""A run's deliverables view each frame once between them (issue 38, item 5): the 24p
movie, the 60i pulldown and its movie share the frames as viewed (telecine.movie.
ViewedFrames), and what they hold is what each made alone holds, pixel for pixel."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np


def _frames(folder: Path, count: int = 8) -> Path:
    """Real EXR frames of a moving gradient with an AOV layer, 32x24."""
    from motion.pipeline.frame_output import write_frame

    folder.mkdir()
    y, x = np.mgrid[0:24, 0:32].astype(np.float32)
    for f in range(count):
        rgba = np.stack([x / 8 + f, y / 6, (x + y + f) / 20, np.ones_like(x)], axis=2)
        write_frame(folder / f"shot.{f:04d}.exr", rgba, {"frame": f}, fps=Fraction(24), aovs={"albedo": rgba[..., :3] * 0.5})
    return folder


def _decoded(path: Path) -> list[np.ndarray]:
    import av

    with av.open(str(path)) as c:
        return [f.to_ndarray(format=f.format.name) for f in c.decode(video=0)]


class CountingView:
    """The real ACES 2.0 view transform, its calls counted (which frames it was shown)."""

    def __init__(self) -> None:
        from motion.pipeline.telecine.movie import ViewTransform

        self.real = ViewTransform()
        self.description, self.color_tags = self.real.description, self.real.color_tags
        self.calls = 0

    def __call__(self, rgba: np.ndarray) -> np.ndarray:
        self.calls += 1
        return self.real(rgba)


def test_24p_and_60i_view_each_frame_once_and_hold_the_same_pixels(tmp_path: Path) -> None:
    from motion.pipeline.frame_output import read_frame
    from motion.pipeline.telecine.deliver import deliver
    from motion.pipeline.telecine.movie import ViewedFrames
    from motion.pipeline.telecine.sequence import discover

    seq = discover(_frames(tmp_path / "frames"))
    view = CountingView()
    shared = ViewedFrames(seq, view)  # type: ignore[arg-type]
    together = deliver(seq.directory, tmp_path / "together", ("24p", "60i"), view=view, sequence=seq, shared=shared)  # type: ignore[arg-type]
    assert view.calls == 8  # (before: 8 for the 24p movie and 8 again for the 60i movie)
    apart = {}
    for fmt in ("24p", "60i"):
        alone = CountingView()
        apart[fmt] = deliver(seq.directory, tmp_path / f"alone-{fmt}", (fmt,), view=alone, sequence=seq,  # type: ignore[arg-type]
                             shared=ViewedFrames(seq, alone, budget_bytes=0))[fmt]  # type: ignore[arg-type]
        assert alone.calls == 8
    for fmt in ("24p", "60i"):
        movie_a, movie_b = together[fmt][-1], apart[fmt][-1]
        a, b = _decoded(movie_a), _decoded(movie_b)
        assert len(a) == (8 if fmt == "24p" else 10) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    for x, y in zip(together["60i"][:-1], apart["60i"][:-1], strict=True):
        fx, fy = read_frame(x), read_frame(y)
        assert np.array_equal(fx.rgba, fy.rgba) and np.array_equal(fx.aovs["albedo"], fy.aovs["albedo"])


def test_a_budget_keeps_what_fits_and_views_the_rest_again(tmp_path: Path) -> None:
    """Past the budget a frame is viewed again when asked for, to the same pixels."""
    from motion.pipeline.telecine.movie import ViewedFrames, viewed
    from motion.pipeline.telecine.sequence import discover

    seq = discover(_frames(tmp_path / "frames"))
    view = CountingView()
    shared = ViewedFrames(seq, view, budget_bytes=3 * 32 * 24 * 3 * 2)  # type: ignore[arg-type]
    first = list(viewed(seq, view, shared=shared))  # type: ignore[arg-type]
    assert view.calls == 8 and sorted(shared.kept) == [0, 1, 2]
    again = list(viewed(seq, view, shared=shared))  # type: ignore[arg-type]
    assert view.calls == 13 and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
