"""`motion` console entry point.

Commands live one module per concern in this package; each module exposes `commands`,
a list of click commands, and COMMANDS below says which module holds each, so a command's
module is imported only when it runs (LazyGroup): `motion validate` loads the scene stage
and nothing of the renderer, the farm or the movies. Modules also import their heavy
dependencies (mitsuba, av, matplotlib) inside the command body.

`main()` is the one place that turns a `MotionError` into one line per problem on stderr
and its exit code (2 for bad input, 3 for an incomplete job, 4 for a disk fault that
stopped the job: docs/farm.md), never a traceback.
"""

from __future__ import annotations

import gc
import importlib
import sys
from typing import Any

import click

from motion.pipeline.errors import MotionError, SceneError

# Each command and the module of motion.cli that defines it (in its `commands` list), in
# the order of `motion --help`. A command's module is imported only when that command runs
# (or for --help): `motion validate` never imports the renderer's, the farm's or the
# movies' stack (tests/cli/test_startup.py checks this table against the modules).
COMMANDS: dict[str, str] = {
    "render": "render",
    "validate": "validate",
    "bake": "bake",
    "plot": "plot",
    "telecine": "telecine",
    "contact-sheet": "telecine",
    "export": "export",
    "view": "export",
    "cache": "cache",
    "info": "info",
    "compare": "compare",
}


class LazyGroup(click.Group):
    """A click group whose commands are imported on first use (COMMANDS)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        """Every command, in COMMANDS order, that this build has."""
        return [name for name in COMMANDS if self.get_command(ctx, name) is not None]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        """The command `name`, importing its module now; None if unknown or not installed."""
        module_name = COMMANDS.get(name)
        if module_name is None:
            return super().get_command(ctx, name)
        try:
            module = importlib.import_module(f"motion.cli.{module_name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"motion.cli.{module_name}":
                return None  # that capability is not installed in this build
            raise
        command = next((c for c in getattr(module, "commands", []) if c.name == name), None)
        if command is not None:
            accept_verbosity_after(command)
        if command is not None and not getattr(command, "start_up_only", False):
            restore_gc()  # a command that works for long collects cycles as usual from here on
        return command


def _verbosity_after(ctx: click.Context, param: click.Parameter, value: int) -> None:
    """-v / -q given after the command (`motion render shot.yaml -q`): added to those given
    before it, and logging set again from the sum."""
    if not value:
        return
    root = ctx.find_root()
    counts = root.meta.setdefault("motion.verbosity", {"verbose": root.params.get("verbose", 0), "quiet": root.params.get("quiet", 0)})
    counts[str(param.name)] += value
    configure_logging(counts["verbose"], counts["quiet"])


def accept_verbosity_after(command: click.Command) -> None:
    """Give `command` the group's -v/-q too (once), so they work before or after it."""
    taken = {opt for p in command.params for opt in getattr(p, "opts", [])}
    for short, name, text in (("-v", "verbose", "More detail on stderr (as `motion -v CMD`)."),
                              ("-q", "quiet", "Less on stderr (as `motion -q CMD`).")):
        if short not in taken and f"--{name}" not in taken:
            command.params.append(click.Option([short, f"--{name}"], count=True, expose_value=False, callback=_verbosity_after, help=text))


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="motion-farm", prog_name="motion")
@click.option("-v", "--verbose", count=True, help="More detail on stderr (-v: each frame as workers report it).")
@click.option("-q", "--quiet", count=True, help="Less on stderr (-q: warnings and errors only, no progress; -qq: errors only).")
def cli(verbose: int, quiet: int) -> None:
    """motion: batch render-farm pipeline for animation (Mitsuba 3, OpenEXR, telecine)."""
    configure_logging(verbose, quiet)


def configure_logging(verbose: int = 0, quiet: int = 0) -> None:
    """The `motion` logger writes plain lines to stderr at INFO, less with -q, more with -v."""
    import logging

    level = max(logging.DEBUG, min(logging.ERROR, logging.INFO - 10 * verbose + 10 * quiet))
    logger = logging.getLogger("motion")
    for handler in list(logger.handlers):
        if getattr(handler, "_motion_cli", False):
            logger.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    handler._motion_cli = True  # type: ignore[attr-defined]
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False


def main(argv: list[str] | None = None, gc_was_enabled: bool | None = None) -> int:
    """Run the CLI and exit with its code (return it when `argv` is given).
    `gc_was_enabled`: the collector's state before the console script turned it off."""
    global _gc_was_enabled
    _gc_was_enabled = gc.isenabled() if gc_was_enabled is None else gc_was_enabled
    gc.disable()
    try:
        code = _run(argv)
    finally:
        if argv is not None:
            restore_gc()
    if argv is None:
        if _nothing_to_finish:
            _exit_now(code)
        sys.exit(code)  # (the collector as the command left it: on, a pass over every object at exit would cost 0.006 s)
    return code


# A command that leaves nothing to finish (`nothing_to_finish`) ends its process without
# the interpreter's teardown: freeing every module and object of the pydantic and click
# stacks one by one is a visible part of a short command such as `motion validate`
# (docs/ci-sharding.md, "What validation keeps"). Its output is flushed first; a command with threads, child processes, temporary files or outputs to
# close never asks for it.
_nothing_to_finish = False


def nothing_to_finish() -> None:
    """Said by a command that starts no thread or process and leaves no temporary file or
    open output: when run as the console script, its process exits without teardown."""
    global _nothing_to_finish
    _nothing_to_finish = True


def _exit_now(code: int) -> None:
    """Flush stdout and stderr, then end the process with `code`, skipping teardown."""
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can be said anyway
            pass
    os._exit(code)


# The cyclic garbage collector is off while the command starts: importing click and pydantic
# and making the scene format's ~75 record classes allocate many objects and free few, and
# the collector's passes over them are wasted (docs/ci-sharding.md, "What validation keeps"). The
# console script (`motion.cli.start`) turns it off before click is imported, `main` when it
# is called otherwise. A command is looked up (LazyGroup.get_command) before it runs: every
# command but those marked `start_up_only` turns it back on there: validate, whose work is
# one bounded scene load (with several scenes it turns the collector on after the first),
# and render, which turns it on once the pipeline's modules are imported, before any work.
# `main` called with arguments leaves it as it found it.
_gc_was_enabled = False


def restore_gc() -> None:
    """The collector back as it was before `main` (or the console script) turned it off."""
    if _gc_was_enabled:
        gc.enable()


# SIGTERM (a farm's scheduler, `timeout`, a container stopping) ends a command as Ctrl-C
# does: the handler raises KeyboardInterrupt where the main thread is, so the farm stops its
# workers, settles the frames in flight as not rendered and writes the report, temporary
# files and claims go, and the process exits 143 (128 + 15) instead of 130. A second SIGTERM
# while that stop runs is ignored (the stop is short; SIGKILL is the scheduler's next word).
_terminated = False


def _on_sigterm(signum: int, frame: Any) -> None:
    global _terminated
    if _terminated:
        return
    _terminated = True
    raise KeyboardInterrupt


def _interrupted() -> int:
    """The one line and exit code of a stop by Ctrl-C (130) or SIGTERM (143)."""
    click.echo("terminated" if _terminated else "interrupted", err=True)
    return 143 if _terminated else 130


def _run(argv: list[str] | None) -> int:
    """Run the CLI with SIGTERM handled as Ctrl-C; returns the process exit code."""
    global _terminated
    import signal
    import threading

    _terminated = False
    if threading.current_thread() is not threading.main_thread():
        return _run_command(argv)
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _run_command(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_command(argv: list[str] | None) -> int:
    """Run the CLI; returns the process exit code."""
    try:
        cli.main(args=argv, prog_name="motion", standalone_mode=False)
    except SceneError as err:
        for problem in err.problems:  # already FILE:LINE:COL: path: message
            click.echo(str(problem), err=True)
        return err.exit_code
    except MotionError as err:
        for line in str(err).splitlines() or [type(err).__name__]:
            click.echo(f"error: {line}", err=True)
        return err.exit_code
    except (click.exceptions.Abort, KeyboardInterrupt):
        return _interrupted()
    except click.ClickException as err:
        # one line, like every other error (click's usage banner is two more)
        hint = f" (see 'motion {err.ctx.command_path.split(' ', 1)[1]} --help')" if isinstance(err, click.UsageError) and err.ctx is not None and " " in err.ctx.command_path else ""
        click.echo(f"error: {err.format_message()}{hint}", err=True)
        return err.exit_code
    except click.exceptions.Exit as err:
        return err.exit_code
    except OSError as err:
        # a disk that refuses a write in any command (export, view, contact-sheet, bake):
        # one line and exit 4, as `motion render` says it (docs/farm.md); others propagate
        from motion.pipeline.frame_output import disk_fault

        fault = disk_fault(err, "writing", err.filename or "?")
        if fault is None:
            raise
        click.echo(f"error: {fault}", err=True)
        return fault.exit_code
    return 0


if __name__ == "__main__":
    main()
