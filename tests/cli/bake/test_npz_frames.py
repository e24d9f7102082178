"""A baked-motion NPZ of many frames: a render reads only the frames it is asked for, and
more frames than any timeline holds is refused."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE
from farm_util import frames_in, motion


def _npz_of(tmp_path: Path, frames: int) -> tuple[Path, Path]:
    """A real bake of a one-ball shot repeated to `frames` frames (compressed: a few MB), and the scene."""
    import numpy as np

    scene = tmp_path / "s.yaml"
    scene.write_text(BASE.replace("last: 1", f"last: {max(frames - 1, 1)}"))
    small = tmp_path / "small.npz"
    assert motion("-q", "bake", scene, "-o", small, "--frames", "0-1").returncode == 0
    with np.load(small) as z:
        arrays = {k: (z[k] if k == "meta" else np.arange(frames, dtype=np.int64) if k == "frames" else np.repeat(z[k][:1], frames, axis=0)) for k in z.files}
    path = tmp_path / "m.npz"
    np.savez_compressed(path, **arrays)
    return path, scene


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_an_npz_of_a_million_frames_renders_the_two_asked_for(tmp_path: Path) -> None:
    path, scene = _npz_of(tmp_path, 1_000_000)
    t0 = time.monotonic()
    res = motion("render", scene, "--motion", path, "--frames", "0-1", "-o", tmp_path / "out", timeout=120)
    assert res.returncode == 0, res.stderr  # before: a record per frame (100,000 frames: 33 s, 2 GB; a million: out of memory)
    assert len(frames_in(tmp_path / "out")) == 2 and time.monotonic() - t0 < 60


def test_an_npz_of_more_frames_than_any_timeline_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.bake import file_format as files
    from motion.pipeline.errors import BakeFileError

    path, _ = _npz_of(tmp_path, 5)
    assert [f.frame for f in files.read_baked(path, frames=[3]).frames] == [3]
    monkeypatch.setattr(files, "MAX_BAKE_FRAMES", 4)
    with pytest.raises(BakeFileError, match="5 frames; the limit is 4"):
        files.read_baked(path, frames=[3])
