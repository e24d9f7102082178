"""Pulldown and its inverse name and write their frames through one record,
`telecine.convert.SequenceOutput`, given whole or as keywords."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.frame_output import read_header, write_frame
from motion.pipeline.telecine.convert import SequenceOutput, inverse_sequence, telecine_sequence


def film(folder: Path, n: int = 4) -> Path:
    for i in range(n):
        rgba = np.full((8, 8, 4), float(i), np.float32)
        write_frame(folder / f"shot.{1 + i:04d}.exr", rgba, {"frame": 1 + i}, fps=Fraction(24))
    return folder


def test_one_output_record_drives_pulldown_and_its_inverse(tmp_path: Path) -> None:
    src = film(tmp_path / "film")
    seen: list[tuple[int, int]] = []
    out = SequenceOutput(out_prefix="v", pixel_type="float", compression="none", progress=lambda done, total: seen.append((done, total)))
    tele = telecine_sequence(src, tmp_path / "60i", output=out)
    assert [p.name for p in tele.paths] == [f"v.{1 + i:04d}.exr" for i in range(5)]  # 4 film frames, 3:2 pad: 5 video frames
    assert seen[-1] == (5, 5)
    assert str(read_header(tele.paths[0])["compression"]).endswith("NO_COMPRESSION")
    back = inverse_sequence(tele.out_dir, tmp_path / "24p", output=SequenceOutput(out_prefix="f", pixel_type="half"))
    assert [p.name for p in back.paths] == [f"f.{1 + i:04d}.exr" for i in range(4)]
    header = read_header(back.paths[0])
    assert str(header["compression"]).endswith("ZIP_COMPRESSION")  # the record's default
    # keywords are the record's fields; one that is not raises before any work
    again = telecine_sequence(src, tmp_path / "60i", out_prefix="v", overwrite=True)
    assert [p.name for p in again.paths] == [p.name for p in tele.paths]
    with pytest.raises(TypeError, match="out_prefx"):
        telecine_sequence(src, tmp_path / "x", out_prefx="v")
