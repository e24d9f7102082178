"""A progress bar for a step that counts items (frames converted, frames encoded): a
transient rich bar on a terminal (stderr), nothing when output is redirected. Steps
take it as a `progress(done, total)` callback (telecine, inverse telecine, movies).

The farm's live bar (farm/progress.py) adds frames per minute, failures and log lines
above the bar for a render.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from typing import Callable, Iterator

CountCallback = Callable[[int, int], None]


@contextmanager
def count_bar(label: str) -> Iterator[CountCallback | None]:
    """A `progress(done, total)` callback drawing a bar on a terminal (stderr), or None
    when stderr is not a terminal (the caller then reports nothing)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total or None)

        yield update
