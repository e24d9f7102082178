"""`motion telecine` and `motion contact-sheet`: parse options, call motion.pipeline.telecine."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from motion.cli.export import view_options
from motion.cli.options import GivenPath, FiniteFloat
from motion.pipeline.errors import FrameIOError, UsageError
from motion.pipeline.count_bar import count_bar

CODEC_NAMES = ["prores", "prores4444", "h264"]


@click.command("telecine")
@click.argument("in_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=GivenPath(file_okay=False, path_type=Path),
              help="Folder for the output EXR sequence.")
@click.option("--pattern", default=None,
              help="3:2 (default), 2:3:3:2, 2:2, blend, or field counts (2:3:3:2, 2332). "
                   "With --inverse: the pattern to assume (default: detect).")
@click.option("--field-order", type=click.Choice(["tff", "bff"]), default=None,
              help="Top or bottom field first (default tff; with --inverse: from the frames' metadata).")
@click.option("--film-speed", default=None,
              help="Film rate: 23.976 (24000/1001 -> 30000/1001, default) or 24 (exact: 24 -> 30), or any rate.")
@click.option("--inverse", is_flag=True, help="Inverse telecine: recover the progressive film frames.")
@click.option("--movie", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also encode the output as a movie (.mov ProRes 422 HQ, .mp4 H.264).")
@click.option("--codec", type=click.Choice(CODEC_NAMES), default=None, help="Movie codec (default from the extension).")
@click.option("--exposure", type=float, default=0.0, show_default=True, help="Movie exposure in stops.")
@click.option("--ocio", "ocio_config", default=None,
              help="OCIO config for the movie's view transform: a .ocio file or a built-in URI "
                   "(default: ocio://cg-config-latest, ACES 2.0 SDR on sRGB; ocio://studio-config-latest; none: the plain sRGB curve).")
@click.option("--ocio-display", default=None, help="OCIO display (default: the config's).")
@click.option("--ocio-view", default=None, help="OCIO view (default: the display's).")
@click.option("--ocio-colorspace", default=None,
              help="OCIO colour space of the frames (default: the config's linear Rec.709, else scene_linear).")
@click.option("--tail", type=click.Choice(["pad", "drop"]), default="pad", show_default=True,
              help="An unpaired last field: complete the frame from the same film frame, or drop it (as FFmpeg).")
@click.option("--drop-frame", is_flag=True, help="Drop-frame timecode (29.97 only).")
@click.option("--tolerance", type=FiniteFloat(min=0), default=0.0, show_default=True,
              help="--inverse detection: mean difference below which two fields count as a repeat.")
@click.option("--prefix", default=None, help="Which sequence of IN_DIR (prefix of prefix.NNNN.exr).")
@click.option("--pixel-type", type=click.Choice(["half", "float"]), default=None,
              help="Output EXR pixel type (default: as the input).")
@click.option("--overwrite", is_flag=True, help="Replace an existing sequence of the same name in OUT.")
def telecine(in_dir: Path, out_dir: Path, pattern: str | None, field_order: str | None, film_speed: str | None,
             inverse: bool, movie: Path | None, codec: str | None, exposure: float, ocio_config: str | None,
             ocio_display: str | None, ocio_view: str | None, ocio_colorspace: str | None, tail: str, drop_frame: bool, tolerance: float,
             prefix: str | None, pixel_type: str | None, overwrite: bool) -> None:
    """Pull a 24p EXR sequence down to 60i (3:2) fields, or back with --inverse."""
    from motion.pipeline.telecine.convert import inverse_sequence, telecine_sequence

    if movie is not None:
        from motion.pipeline.telecine.movie import ViewTransform, choose_codec

        choose_codec(movie, codec)  # a bad extension or codec fails before any work
        view = ViewTransform(exposure, ocio_config, ocio_display, ocio_view, ocio_colorspace)
    elif ocio_config is not None or ocio_display or ocio_view or ocio_colorspace:
        raise UsageError("--ocio applies to the movie; give --movie FILE")
    with count_bar("telecine" if not inverse else "inverse telecine") as progress:
        if inverse:
            if drop_frame:
                raise UsageError("--drop-frame applies to telecine, not --inverse")
            result = inverse_sequence(in_dir, out_dir, pattern=pattern, field_order=field_order,
                                      film_speed=film_speed, tolerance=tolerance, prefix=prefix,
                                      pixel_type=pixel_type, overwrite=overwrite, progress=progress)
        else:
            result = telecine_sequence(in_dir, out_dir, pattern=pattern or "3:2", field_order=field_order or "tff",
                                       film_speed=film_speed or "23.976", tail=tail,  # type: ignore[arg-type]
                                       drop_frame=drop_frame, prefix=prefix, pixel_type=pixel_type,
                                       overwrite=overwrite, progress=progress, sequence=_timeline_sequence(in_dir, prefix, even=pattern != "blend"))
    how = result.cadence.name + (f" phase {result.detection.phase} (detected)" if result.detection else "")
    order = f", {result.field_order}" if result.field_order and not inverse else ""
    from motion.pipeline.timeline import rate_label

    click.echo(f"wrote {len(result.paths)} frames to {result.out_dir} ({how}{order}, {rate_label(result.rate)})")
    if movie is not None:
        from motion.pipeline.telecine.movie import sequence_movie

        with count_bar("movie") as progress:
            path = sequence_movie(result.out_dir, movie, rate=result.rate, codec=codec, view=view,
                                  prefix=result.paths[0].name.rsplit(".", 2)[0], progress=progress)
        click.echo(f"wrote {path} ({rate_label(result.rate)}{', interlaced' if result.field_order and not inverse else ''})")


def _timeline_sequence(in_dir: Path, prefix: str | None, allow_gaps: bool = False, even: bool = False) -> Any:
    """A shot's output folder holding frames outside its timeline (a render from before
    `first: 1001`): the timeline's frames only, the foreign ones named in a warning
    (shot/stale.py: shot_folder_frames). None otherwise: the folder's one sequence."""
    from motion.pipeline.shot.stale import shot_folder_frames

    shot = shot_folder_frames(in_dir, prefix)
    if shot is None or not shot[1].foreign or not shot[1].timeline:
        return None
    loaded, found = shot
    from motion.pipeline.farm.selection import format_frames
    from motion.pipeline.timeline import format_range
    from motion.pipeline.telecine.sequence import sequence_of

    timeline = loaded.scene.timeline
    click.echo(f"motion: {in_dir}: warning: frames {format_frames(sorted(found.foreign))} lie outside the timeline {format_range(timeline.first, timeline.last)} "
               f"of {loaded.path}: foreign, left out", err=True)
    name = next(iter(found.timeline.values())).name.rsplit(".", 2)[0]
    seq = sequence_of(found.timeline, name, directory=in_dir, require_even_height=even)
    if seq.missing and not allow_gaps:
        raise FrameIOError(f"{in_dir}: frames {seq.missing.text()} of sequence {name} ({format_range(seq.numbers[0], seq.numbers[-1])}) are missing")
    return seq


@click.command("contact-sheet")
@click.argument("in_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("-o", "--out", "out_path", required=True, type=GivenPath(dir_okay=False, path_type=Path),
              help="PNG file to write.")
@click.option("--width", "thumb_width", type=int, default=240, show_default=True, help="Thumbnail width in pixels.")
@click.option("--columns", type=int, default=None, help="Thumbnails per row (default: about 16:9 overall).")
@click.option("--max-frames", type=int, default=60, show_default=True, help="Sample every k-th frame above this.")
@view_options
def contact_sheet(in_dir: Path, out_path: Path, thumb_width: int, columns: int | None, max_frames: int,
                  exposure: float, ocio_config: str | None, ocio_display: str | None, ocio_view: str | None,
                  ocio_colorspace: str | None, prefix: str | None) -> None:
    """A PNG grid of tone-mapped thumbnails of an EXR sequence, with frame numbers (gaps allowed)."""
    from motion.pipeline.telecine.contact_sheet import contact_sheet as make_sheet
    from motion.pipeline.telecine.movie import ViewTransform
    from motion.pipeline.telecine.sequence import discover

    view = ViewTransform(exposure, ocio_config, ocio_display, ocio_view, ocio_colorspace)  # bad options first
    seq = _timeline_sequence(in_dir, prefix, allow_gaps=True) or discover(in_dir, prefix, require_even_height=False, allow_gaps=True)
    path = make_sheet(seq, out_path, thumb_width=thumb_width, columns=columns, max_frames=max_frames, view=view)
    missing = f", {len(seq.missing)} missing" if seq.missing else ""
    click.echo(f"wrote {path} ({len(seq)} frames{missing})")


commands = [telecine, contact_sheet]
