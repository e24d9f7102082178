"""`motion bake`: evaluated motion per frame across the shutter, written as JSON or NPZ."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("bake")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="FILE.json (rigid transforms and scalars) or FILE.npz (also vertices and particles).")
@click.option("--frames", help="A-B, N or a comma list of those (default: the scene's timeline).")
def bake(scene: Path, output: Path, frames: str | None) -> None:
    """Evaluate SCENE's motion at every frame and across its shutter; write it to a file."""
    import time

    from motion.pipeline.bake import bake as bake_motion
    from motion.pipeline.bake import parse_frames, summary, write_baked
    from motion.pipeline.scene import load_scene

    t0 = time.perf_counter()
    loaded = load_scene(scene)
    baked = bake_motion(loaded, parse_frames(frames, loaded))
    write_baked(baked, output)
    s = summary(baked)
    click.echo(
        f"{output}: {s['frames']} frames x {s['samples_per_frame']} shutter samples, {s['objects']} objects, "
        f"{s['lights']} lights, {s['deforming']} deforming, {s['particle_systems']} particle systems "
        f"({time.perf_counter() - t0:.2f} s)"
    )


commands = [bake]
