"""The two YAML readers (libyaml's fast path and PyYAML alone, scene/source.py) give one
meaning: the same data and positions, or the same located problems, on any mutation."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _scenes import TWO_FRAMES as BASE
from tests.scene.test_validation import _parse_both


BOM = "\ufeff"


_PIECES = ["\t", BOM, "!", " ", "\n", ":", "- ", "#", "'", '"', "[", "]", "{", "}", ",", "&a ", "*a", "? ", "|", ">", "%", "\r", "\\"]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.integers(0, 10_000), st.sampled_from(_PIECES)), min_size=1, max_size=4))
def test_fuzz_the_two_readers_agree_on_every_mutation(monkeypatch: pytest.MonkeyPatch, edits: list[tuple[int, str]]) -> None:
    """A scene with tabs, BOMs, tags and YAML punctuation put anywhere: libyaml's fast path
    and PyYAML alone give the same data and positions, or the same located problems."""
    text = BASE + "materials: [{name: m, type: diffuse, color: 0.5}]\n"
    for at, piece in edits:
        at %= len(text) + 1
        text = text[:at] + piece + text[at:]
    fast, slow = _parse_both(text, monkeypatch)
    assert fast == slow, text
