"""Cadences (telecine/cadence.py): the documented pulldown tables in either field order, the
output rates, general cadence strings, and how a sequence's tail is padded or dropped."""

from __future__ import annotations

from fractions import Fraction

import pytest

from _telecine_frames import TABLES
from motion.pipeline.errors import UsageError
from motion.pipeline.telecine.cadence import field_sources, output_rate, parse_cadence, plan


@pytest.mark.parametrize("pattern", sorted(TABLES))
@pytest.mark.parametrize("order", ["tff", "bff"])
def test_cadence_tables(pattern: str, order: str) -> None:
    frames = plan(4, parse_cadence(pattern), order)  # type: ignore[arg-type]
    assert [(v.top, v.bottom) for v in frames] == (
        TABLES[pattern] if order == "tff" else [(b, t) for t, b in TABLES[pattern]]
    )
    # Fields in time order: the first field has the order's parity.
    sources = field_sources(4, parse_cadence(pattern))
    assert [s for v in frames for s in (v.first, v.second)] == sources
    assert len(sources) == (10 if pattern != "2:2" else 8)


def test_cadence_rates_and_general_strings() -> None:
    assert output_rate(Fraction(24000, 1001), parse_cadence("3:2")) == Fraction(30000, 1001)
    assert output_rate(Fraction(24), parse_cadence("2:3:3:2")) == 30
    assert output_rate(Fraction(25), parse_cadence("2:2")) == 25
    # 24p -> 50i "Euro pulldown": 11 frames of 2 fields and one of 3, twice: 24 -> 25.
    euro = parse_cadence("222222222223")
    assert output_rate(Fraction(24), euro) == 25
    assert parse_cadence("32").counts == (3, 2)
    with pytest.raises(UsageError, match="unknown pulldown"):
        parse_cadence("3-2")


@pytest.mark.parametrize("n,pad,drop", [(5, 6, 6), (6, 8, 7), (7, 9, 8), (3, 4, 3), (1, 1, 1)])
def test_partial_tails(n: int, pad: int, drop: int) -> None:
    cad = parse_cadence("3:2")
    padded, dropped = plan(n, cad, "tff", "pad"), plan(n, cad, "tff", "drop")
    assert (len(padded), len(dropped)) == (pad, drop)
    # pad: every film frame appears in both parities of some frame.
    assert {v.top for v in padded} == {v.bottom for v in padded} == set(range(n))
