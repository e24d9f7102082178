"""`motion cache info|clear`: the shared on-disk caches (converted assets, drjit kernels)."""

from __future__ import annotations

from pathlib import Path

import click


def _folders() -> dict[str, Path]:
    from motion.pipeline.cache import kernels_dir
    from motion.pipeline.render.assets import assets_dir

    return {"assets": assets_dir(), "kernels": kernels_dir()}


@click.group("cache")
def cache() -> None:
    """Inspect or clear motion's on-disk caches (shared by all workers on this machine)."""


@cache.command("info")
def cache_info() -> None:
    """Files and bytes in each cache folder."""
    from motion.pipeline.render.assets import info

    for name, folder in _folders().items():
        i = info(folder)
        click.echo(f"{name:<8} {i.files:>6} files {i.bytes / 1e6:>10.1f} MB  {folder}")


@cache.command("clear")
@click.option("--what", type=click.Choice(["all", "assets", "kernels"]), default="all", show_default=True)
def cache_clear(what: str) -> None:
    """Delete cached files (they are rebuilt on demand)."""
    from motion.pipeline.render.assets import clear

    for name, folder in _folders().items():
        if what in ("all", name):
            click.echo(f"{name}: removed {clear(folder)} files from {folder}")


commands = [cache]
