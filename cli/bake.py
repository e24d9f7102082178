"""`motion bake`: evaluated motion per frame across the shutter, written as JSON or NPZ."""

from __future__ import annotations

from pathlib import Path

import click

from motion.cli.options import GivenPath


@click.command("bake")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True, type=GivenPath(dir_okay=False, path_type=Path),
              help="FILE.json (rigid transforms and scalars) or FILE.npz (also vertices and particles across the shutter).")
@click.option("--frames", help="Frames as for `motion render`: 0-119, 0-119x2, 1,5,9 or mixes (default: the scene's timeline).")
@click.option("--preset", help="Bake with a render preset applied (its shutter_samples), to match a render that uses it.")
def bake(scene: Path, output: Path, frames: str | None, preset: str | None) -> None:
    """Evaluate SCENE's motion at every frame and across its shutter; write it to a file."""
    import time

    from motion.pipeline.bake import bake as bake_motion
    from motion.pipeline.bake import summary, write_baked
    from motion.pipeline.farm.selection import parse_frames
    from motion.pipeline.presets import load_preset, overrides_from
    from motion.pipeline.scene import load_scene

    t0 = time.perf_counter()
    loaded = load_scene(scene, overrides_from(load_preset(preset)[0], {}) if preset else None)
    timeline = loaded.scene.timeline
    selected = parse_frames(frames, timeline.first, timeline.last) if frames else list(timeline.timeline().frames)
    baked = bake_motion(loaded, selected)
    write_baked(baked, output)
    s = summary(baked)
    click.echo(
        f"{output}: {s['frames']} frames x {s['samples_per_frame']} shutter samples, {s['objects']} objects, "
        f"{s['lights']} lights, {s['deforming']} deforming, {s['particle_systems']} particle systems "
        f"({time.perf_counter() - t0:.2f} s)"
    )
    if output.suffix.lower() == ".json" and (s["deforming"] or s["particle_systems"]):
        click.echo(f"note: JSON carries rigid poses only: the deforming meshes and particle systems are not in {output}; "
                   "bake to .npz to render them with --motion", err=True)


commands = [bake]
