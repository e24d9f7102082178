"""`motion info`: the renderer variant and why, LLVM, threads, cache folders, versions, and
the denoiser (Intel Open Image Denoise through mitsuba-oidn) with its version."""

from __future__ import annotations

import json

import click


@click.command("info")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(as_json: bool) -> None:
    """Show the renderer variant motion will use, its LLVM library, threads, caches, versions."""
    from motion.pipeline.variant import info as gather

    from motion.pipeline.render.output.denoise import PACKAGE, describe, probe

    data = gather()
    found = probe()  # runs the library in a subprocess: a broken install shows here
    data["denoiser"] = {"name": "oidn", "package": PACKAGE, **found, "description": None if "error" in found else describe(found)}
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    fallback = "  (FALLBACK: slow)" if data["fallback"] else ""
    click.echo(f"variant        {data['variant']}{fallback}  -- {data['reason']}")
    click.echo(f"llvm library   {data['llvm_library'] or '-'}  (version {data['llvm_version'] or '-'})")
    click.echo(f"threads        {data['threads']}")
    click.echo(f"cache root     {data['cache_root']}")
    click.echo(f"kernel cache   {data['kernel_cache']}")
    click.echo(f"asset cache    {data['asset_cache']}")
    denoiser = data["denoiser"]
    if "error" in denoiser:  # type: ignore[operator]
        click.echo(f"denoiser       unavailable: {PACKAGE}: {denoiser['error']}")  # type: ignore[index]
    else:
        click.echo(f"denoiser       {denoiser['description']}")  # type: ignore[index]
    click.echo(f"python         {data['python']}")
    for name, version in data["packages"].items():  # type: ignore[union-attr]
        click.echo(f"{name:<14} {version}")


commands = [info]
