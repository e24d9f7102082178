"""Live progress: a rich bar on a terminal (frames done/total, frames per minute, ETA,
failures), plain log lines otherwise (CI logs, files)."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


class Progress:
    """Counts frames as the scheduler reports them and shows them."""

    def __init__(self, total: int, already: int = 0, label: str = "render", stream: TextIO | None = None, live: bool | None = None) -> None:
        self.stream = stream or sys.stderr
        self.total = total
        self.done = already
        self.already = already
        self.failed = 0
        self.retries = 0
        self.label = label
        self.t0 = time.monotonic()
        self.live = self.stream.isatty() if live is None else live
        self._bar: Any = None
        self._task: Any = None
        self._last_line = 0.0

    # frames rendered in this run, per minute
    @property
    def rate_fpm(self) -> float:
        dt = time.monotonic() - self.t0
        return 60.0 * (self.done - self.already) / dt if dt > 0 else 0.0

    @property
    def eta_s(self) -> float | None:
        rate = self.rate_fpm / 60.0
        left = self.total - self.done - self.failed
        return left / rate if rate > 0 else None

    def __enter__(self) -> "Progress":
        if self.live:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as Bar, TextColumn, TimeElapsedColumn, TimeRemainingColumn

            self._bar = Bar(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[fpm]:.1f} fr/min"),
                TextColumn("failed {task.fields[failed]}"),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                console=Console(file=self.stream),
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=self.total, completed=self.done, fpm=0.0, failed=0)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._bar is not None:
            self._refresh()
            self._bar.stop()

    def log(self, message: str) -> None:
        if self._bar is not None:
            self._bar.console.print(message)
        else:
            print(message, file=self.stream, flush=True)

    def _refresh(self) -> None:
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done + self.failed, fpm=self.rate_fpm, failed=self.failed)

    def event(self, kind: str, data: dict[str, Any]) -> None:
        """Scheduler notifications: rendered, skipped, done_elsewhere, failed, retry,
        excluded, held."""
        if kind in ("rendered", "skipped", "done_elsewhere"):
            self.done += 1
        elif kind == "failed":
            self.failed += 1
            self.log(f"  frame {data['frame']} FAILED: {data.get('error')}")
        elif kind == "retry":
            self.retries += 1
            f = data["frames"]
            self.log(f"  retrying frames {f[0]}-{f[-1]} (attempt {data['attempt'] + 1}): {data['error']}")
        elif kind == "excluded":
            self.log(f"  worker {data['worker']} excluded for this job: {data['reason']}")
        elif kind == "held":
            self.log(f"  frame {data['frame']} is being rendered by another job ({data['holder']}); waiting")
        self._refresh()
        if self._bar is None and kind in ("rendered", "skipped", "done_elsewhere", "failed"):
            now = time.monotonic()
            finished = self.done + self.failed >= self.total
            if finished or now - self._last_line >= 2.0:
                self._last_line = now
                eta = self.eta_s
                eta_txt = f", ETA {eta:.0f}s" if eta is not None and not finished else ""
                print(
                    f"  {self.label}: {self.done}/{self.total} frames, {self.rate_fpm:.1f} frames/min, {self.failed} failed{eta_txt}",
                    file=self.stream,
                    flush=True,
                )
