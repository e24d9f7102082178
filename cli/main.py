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

import importlib
import sys

import click

from motion.pipeline.errors import MotionError, SceneError

# Each command and the module of motion.cli that defines it (in its `commands` list), in
# the order of `motion --help`. A command's module is imported only when that command runs
# (or for --help): `motion validate` never imports the renderer's, the farm's or the
# movies' stack (tests/test_cli_startup.py checks this table against the modules).
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
        return next((c for c in getattr(module, "commands", []) if c.name == name), None)


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


def main(argv: list[str] | None = None) -> int:
    """The `motion` console entry point: runs the CLI and exits with its code (returns it when `argv` is given)."""
    code = _run(argv)
    if argv is None:
        sys.exit(code)
    return code


def _run(argv: list[str] | None) -> int:
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
    except click.exceptions.Abort:
        click.echo("interrupted", err=True)
        return 130
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        return 130
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
