"""Live progress: a rich bar on a terminal (frames done/total, frames per minute, ETA,
failures), plain log lines otherwise (CI logs, files).

Lines go through the `motion` logger (INFO: plans, progress, summaries; WARNING: failures,
retries, excluded workers; DEBUG: each frame as a worker reports it). `motion -q` / `-v`
set its level (cli/main.py); a library caller configures logging as it likes. The live
bar draws on the terminal only when INFO is enabled."""

from __future__ import annotations

import logging
import sys
import time
from typing import Any, TextIO

log = logging.getLogger("motion")


class Progress:
    """Counts frames as the scheduler reports them and shows them."""

    def __init__(self, total: int, already: int = 0, label: str = "render", stream: TextIO | None = None, live: bool | None = None,
                 estimate_s: float | None = None, overhead_s: float = 0.0) -> None:
        """`live`: True draws the bar, None draws it on a terminal (plain lines every 2 s
        elsewhere, for CI logs), False (--no-progress) shows neither: only the warnings
        and the summary. `estimate_s`: the plan's estimate of a frame's cost in worker
        seconds divided by the workers (the ETA before two frames are done); `overhead_s`:
        the plan's start-up and cold first frames, counted down from the start until then."""
        self.stream = stream or sys.stderr
        self.quiet = live is False
        self.estimate_s = estimate_s
        self.overhead_s = overhead_s
        self._first_done: float | None = None  # when this run's first frame was done
        self.total = total
        self.done = already
        self.already = already
        self._counted: set[int] = set()  # frames counted done (written, then confirmed)
        self.failed = 0
        self.retries = 0
        self.label = label
        self.t0 = time.monotonic()
        self.live = (self.stream.isatty() if live is None else live) and log.isEnabledFor(logging.INFO)
        self._bar: Any = None
        self._task: Any = None
        self._last_line = 0.0

    # frames rendered in this run, per minute
    @property
    def rate_fpm(self) -> float:
        """Frames rendered in this run per minute (frames already complete do not count)."""
        dt = time.monotonic() - self.t0
        return 60.0 * (self.done - self.already) / dt if dt > 0 else 0.0

    @property
    def eta_s(self) -> float | None:
        """Seconds until every frame is done. The rate is measured from the first frame
        done, not from the start: start-up and the workers' cold first frames (kernel
        compilation) would otherwise make the first ETAs several times too long. Before a
        second frame, the plan's estimate per frame and what is left of its start-up and
        cold costs, if any; else None."""
        left = self.total - self.done - self.failed
        run_done = self.done - self.already
        if self._first_done is not None and run_done >= 2:
            dt = time.monotonic() - self._first_done
            if dt > 0:
                return left * dt / (run_done - 1)
        if self.estimate_s is not None:
            return max(0.0, self.overhead_s - (time.monotonic() - self.t0)) + left * self.estimate_s
        return None

    def __enter__(self) -> "Progress":
        if self.live:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as Bar, TextColumn, TimeElapsedColumn, TimeRemainingColumn

            self._bar = Bar(
                TextColumn("[bold]{task.description}"),
                # a healthy bar is green (rich's default pink reads as an error); red only when frames failed
                BarColumn(complete_style="green", finished_style="bold green"),
                MofNCompleteColumn(),
                TextColumn("{task.fields[fpm]:.1f} fr/min"),
                TextColumn("{task.fields[failed_text]}"),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                console=Console(file=self.stream),
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=self.total, completed=self.done, fpm=0.0, failed=0, failed_text="[dim]0 failed")
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._bar is not None:
            self._refresh()
            self._bar.stop()

    def note(self, message: str) -> None:
        """A line about the run's progress (its plan, the executor): INFO, or DEBUG with
        --no-progress, which leaves only the warnings and the summary."""
        self.log(message, logging.DEBUG if self.quiet else logging.INFO)

    def log(self, message: str, level: int = logging.INFO) -> None:
        """One line: above the live bar when there is one, else through the logger."""
        if self._bar is not None and log.isEnabledFor(level):
            self._bar.console.print(message, markup=False, highlight=False)
        else:
            log.log(level, message)

    def _refresh(self) -> None:
        if self._bar is not None:
            failed_text = f"[bold red]{self.failed} failed" if self.failed else "[dim]0 failed"
            self._bar.update(self._task, completed=self.done + self.failed, fpm=self.rate_fpm, failed=self.failed, failed_text=failed_text)
            if self.failed:
                self._bar.columns[1].complete_style = "red"

    def event(self, kind: str, data: dict[str, Any]) -> None:
        """Scheduler notifications: written (a worker finished a frame; its chunk is still
        running), rendered, skipped, done_elsewhere, failed, retry, excluded, held. A frame
        is counted once, when it is first reported written or done."""
        if kind == "written":
            seconds = data.get("seconds")
            took = f" in {seconds:.2f}s" if isinstance(seconds, (int, float)) and seconds > 0 else ""
            self.log(f"  frame {data.get('frame')}: {data.get('path') or '?'}{took} ({data.get('worker')})", logging.DEBUG)
        if kind in ("written", "rendered", "skipped", "done_elsewhere"):
            frame = data.get("frame")
            if frame in self._counted:
                return
            if frame is not None:
                self._counted.add(frame)
            self.done += 1
            if kind in ("written", "rendered") and self._first_done is None:
                self._first_done = time.monotonic()
        elif kind == "failed":
            self.failed += 1
            self.log(f"  frame {data['frame']} FAILED: {data.get('error')}", logging.WARNING)
        elif kind == "retry":
            self.retries += 1
            f = data["frames"]
            from ..timeline import format_range

            self.log(f"  retrying frames {format_range(f[0], f[-1])} (attempt {data['attempt'] + 1}): {data['error']}", logging.WARNING)
        elif kind == "excluded":
            self.log(f"  worker {data['worker']} excluded for this job: {data['reason']}", logging.WARNING)
        elif kind == "held":
            self.log(f"  frame {data['frame']} is being rendered by another job ({data['holder']}); waiting")
        self._refresh()
        if self._bar is None and not self.quiet and kind in ("written", "rendered", "skipped", "done_elsewhere", "failed"):
            now = time.monotonic()
            finished = self.done + self.failed >= self.total
            if finished or now - self._last_line >= 2.0:
                self._last_line = now
                eta = self.eta_s
                eta_txt = f", ETA {eta:.0f}s" if eta is not None and not finished else ""
                log.info(f"  {self.label}: {self.done}/{self.total} frames, {self.rate_fpm:.1f} frames/min, {self.failed} failed{eta_txt}")


class BakeProgress:
    """The bake's status before any frame renders: the simulation's progress in simulated
    seconds per second with an ETA (a line every 2 s, or one line redrawn on a terminal),
    then one summary line (time simulated, rate, frames baked)."""

    def __init__(self, stream: TextIO | None = None, live: bool | None = None, every_s: float = 2.0) -> None:
        self.stream = stream or sys.stderr
        self.live = (self.stream.isatty() if live is None else live) and log.isEnabledFor(logging.INFO)
        self.quiet = live is False  # --no-progress: the bake's lines at DEBUG only
        self.every_s = every_s
        self.t0 = time.monotonic()
        self._last = self.t0
        self._sim_end: float | None = None
        self._simulated = 0.0  # seconds simulated in finished groups
        self._group_t = 0.0
        self._span = 0.0
        self._groups = 0
        self._sim_wall = 0.0
        self._drawn = False

    def __enter__(self) -> "BakeProgress":
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._drawn and self.live:
            print(file=self.stream, flush=True)

    def simulated(self, t: float, t_start: float, t_end: float) -> None:
        """The simulation reached `t` of [t_start, t_end] (one call per few steps)."""
        span = t_end - t_start
        done = t - t_start
        if done < self._group_t or self._groups == 0:  # a new group (bodies, then each particle system)
            self._simulated += self._group_t
            self._groups += 1
        self._group_t, self._span = done, span
        now = time.monotonic()
        self._sim_wall = now - self.t0
        if now - self._last < self.every_s:
            return
        self._last = now
        rate = (self._simulated + done) / self._sim_wall if self._sim_wall > 0 else 0.0
        eta = (span - done) / rate if rate > 0 else float("inf")
        group = f" (group {self._groups})" if self._groups > 1 else ""
        line = f"  bake: simulated {done:.2f} of {span:.2f} s{group}, {rate:.3g} simulated s per s, ETA {eta:.0f} s"
        if self.live:
            print("\r" + line, end="", file=self.stream, flush=True)
            self._drawn = True
        else:
            log.log(logging.DEBUG if self.quiet else logging.INFO, line)

    def baked(self, frames: int) -> None:
        """The bake is done: one summary line."""
        total = time.monotonic() - self.t0
        if self._drawn and self.live:
            print(file=self.stream)
            self._drawn = False
        simulated = self._simulated + self._group_t
        if self._groups:
            rate = simulated / self._sim_wall if self._sim_wall > 0 else float("inf")
            sim = f"simulated {simulated:.2f} s of dynamics in {self._sim_wall:.2f} s ({rate:.3g} simulated s per s), "
        else:
            sim = ""
        log.log(logging.DEBUG if self.quiet else logging.INFO, f"motion: bake: {sim}{frames} frames baked in {total:.2f} s")
