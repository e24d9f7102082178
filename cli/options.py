"""Option types shared by the commands: numbers that must be finite (click's FloatRange
lets NaN through, since every comparison with NaN is false) and paths that must not be
empty (click's Path makes `-o ''` the current folder)."""

from __future__ import annotations

import math
from typing import Any

import click

from motion.pipeline.farm.claims import MAX_STALE_AFTER_S


class FiniteFloat(click.FloatRange):
    """A finite float within [min, max] (either open where asked): NaN and infinities are
    refused with click's one-line usage error (exit 2)."""

    name = "finite float"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        """The number, or a usage error naming it when it is NaN, infinite or out of range."""
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


class GivenPath(click.Path):
    """A path that says something: `-o ''` (an unset variable in a farm script) is refused
    with one usage line, not taken as the current folder (pathlib reads '' as '.')."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        """The path, or a usage error when it is empty or only white space."""
        if isinstance(value, str) and not value.strip():
            self.fail("an empty path (name a folder or file; '.' for the current folder)", param, ctx)
        return super().convert(value, param, ctx)


# A chunk's timeout is also how old another host's claim must be to count as stale: at most
# the claims' own bound (a week), so a claim is never protected forever
MAX_TASK_TIMEOUT_S = MAX_STALE_AFTER_S
