"""A kept frame's header read from its bytes (frame_output.plain_meta) gives exactly what
the OpenEXR bindings give (read_meta), and anything it cannot read is left to them."""

from __future__ import annotations

import numpy as np
from pathlib import Path

from motion.pipeline.frame_output import plain_meta, read_meta, write_frame


def _frame(path: Path, meta: dict) -> Path:
    write_frame(path, np.full((6, 8, 4), 0.5, np.float32), meta=meta)
    return path


def test_plain_meta_reads_what_the_bindings_read(tmp_path: Path) -> None:
    meta = {"frame": 7, "look_hash": "0123456789abcdef", "time": 0.1, "spp": 4, "look_parts": '{"m0": "x"}', "scene": "/tmp/é.yaml"}
    path = _frame(tmp_path / "a.exr", meta)
    assert plain_meta(path) == read_meta(path)
    assert plain_meta(path)["time"] == read_meta(path)["time"] != 0.1  # stored as a 32-bit float, read back as the bindings do


def test_plain_meta_leaves_other_files_to_the_bindings(tmp_path: Path) -> None:
    path = _frame(tmp_path / "a.exr", {"frame": 1})
    data = path.read_bytes()
    (tmp_path / "cut.exr").write_bytes(data[:40])
    (tmp_path / "foreign.exr").write_bytes(b"P6\n1 1\n255\n\0\0\0")
    multipart = bytearray(data)
    multipart[5] |= 0x10  # the multi-part flag
    (tmp_path / "multi.exr").write_bytes(bytes(multipart))
    for name in ("cut.exr", "foreign.exr", "multi.exr", "missing.exr"):
        assert plain_meta(tmp_path / name) is None, name
