"""The field model (pipeline/field_model.py): a frame split into its two fields and woven again
is the frame."""

from __future__ import annotations

import numpy as np

from _telecine_frames import H, W, ident
from motion.pipeline.field_model import field, split, weave, weave_frames


def test_field_split_and_weave_are_inverse() -> None:
    frame = ident(7)
    top, bottom = split(frame)
    assert top.shape == (H // 2, W, 4) and np.shares_memory(top, frame)
    assert (top[..., 1][:, 0] == np.arange(0, H, 2)).all()
    assert (bottom[..., 1][:, 0] == np.arange(1, H, 2)).all()
    assert np.array_equal(weave(top, bottom), frame)
    odd = np.arange(5 * 3).reshape(5, 3)
    assert np.array_equal(weave(*split(odd)), odd)
    mixed = weave_frames(ident(1), ident(2))
    assert (field(mixed, "top")[..., 0] == 1).all() and (field(mixed, "bottom")[..., 0] == 2).all()
