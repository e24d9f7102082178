"""`motion render`: scene -> baked motion -> frames on disk (-> deliverables)."""

from __future__ import annotations

from pathlib import Path

import click

from motion.pipeline.errors import UsageError


def _resolution(value: str | None) -> tuple[int, int] | None:
    if value is None:
        return None
    try:
        w, h = (int(x) for x in value.lower().split("x"))
    except ValueError:
        raise UsageError(f"--resolution expects WIDTHxHEIGHT such as 640x360, got {value!r}") from None
    if w < 1 or h < 1:
        raise UsageError(f"--resolution must be positive, got {value!r}")
    return (w, h)


@click.command("render")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output_dir", type=click.Path(file_okay=False, path_type=Path), help="Output folder (default: the scene's output.directory, else out/<name>).")
@click.option("--frames", "frames_spec", help="Frames to render: 0-119, 0-119x2, 1,5,9 or mixes (default: the scene's timeline).")
@click.option("--preset", help="Render preset: ci-smoke, preview, final, or a path to a preset .yaml.")
@click.option("--spp", type=click.IntRange(min=1), help="Samples per pixel (overrides preset and scene).")
@click.option("--resolution", help="WIDTHxHEIGHT (overrides preset and scene).")
@click.option("--motion-blur", type=click.Choice(["stochastic", "subframes", "off"]), help="Motion-blur mode.")
@click.option("--variant", type=click.Choice(["auto", "llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb"]), help="Mitsuba variant (default: auto).")
@click.option("--no-cache", is_flag=True, help="Naive path for comparison: a fresh Mitsuba scene for every frame.")
@click.option("--deliver", "deliver_spec", help="After the last frame, assemble deliverables: 24p,60i,50i,review,contact.")
def render(
    scene: Path,
    output_dir: Path | None,
    frames_spec: str | None,
    preset: str | None,
    spp: int | None,
    resolution: str | None,
    motion_blur: str | None,
    variant: str | None,
    no_cache: bool,
    deliver_spec: str | None,
) -> None:
    """Render SCENE's frames to OpenEXR files."""
    from motion.pipeline.render.run import RenderRequest, run_render

    request = RenderRequest(
        scene=scene,
        output_dir=output_dir,
        frames_spec=frames_spec,
        preset=preset,
        render_overrides={"spp": spp, "resolution": _resolution(resolution), "motion_blur": motion_blur, "variant": variant},
        cache=not no_cache,
        deliver=deliver_spec,
    )
    run_render(request)


commands = [render]
