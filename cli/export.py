"""`motion export` (EXR -> PNG/JPEG through the movies' view transform) and `motion view`
(an HTML flipbook of a rendered sequence, opened in the user's browser on request)."""

from __future__ import annotations

from pathlib import Path

import click

from motion.cli.options import GivenPath

_VIEW_OPTIONS = [
    click.option("--exposure", type=float, default=0.0, show_default=True, help="Exposure in stops (as the movies)."),
    click.option("--ocio", "ocio_config", default=None, help="OCIO config for the view transform: a .ocio file or a built-in ocio://NAME (default: ocio://cg-config-latest, ACES 2.0 SDR on sRGB; none: the plain sRGB curve)."),
    click.option("--ocio-display", default=None, help="OCIO display (default: the config's)."),
    click.option("--ocio-view", default=None, help="OCIO view (default: the display's)."),
    click.option("--ocio-colorspace", default=None, help="OCIO colour space of the frames."),
    click.option("--prefix", default=None, help="Which sequence of IN_DIR (prefix of prefix.NNNN.exr)."),
]


def view_options(f):  # type: ignore[no-untyped-def]
    """The view-transform options of every command that shows frames (export, view,
    contact-sheet): --exposure, --ocio (default: OCIO's ACES 2.0 SDR; none: plain sRGB),
    --ocio-display, --ocio-view, --ocio-colorspace, --prefix."""
    for option in reversed(_VIEW_OPTIONS):
        f = option(f)
    return f


@click.command("export")
@click.argument("in_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["png", "jpg"]), default="png", show_default=True, help="Image format (8 bits per channel).")
@click.option("-o", "--out", "out_dir", type=GivenPath(file_okay=False, path_type=Path), help="Folder for the images (default: IN_DIR/png or IN_DIR/jpg).")
@click.option("--quality", type=click.IntRange(1, 95), default=92, show_default=True, help="JPEG quality.")
@view_options
def export(in_dir: Path, fmt: str, out_dir: Path | None, quality: int, exposure: float, ocio_config: str | None,
           ocio_display: str | None, ocio_view: str | None, ocio_colorspace: str | None, prefix: str | None) -> None:
    """Write each EXR frame of IN_DIR as a PNG or JPEG, with the movies' view transform."""
    from motion.pipeline.telecine.export import export_images

    from motion.pipeline.telecine.movie import ViewTransform

    view = ViewTransform(exposure, ocio_config, ocio_display, ocio_view, ocio_colorspace)
    done = export_images(in_dir, out_dir or Path(in_dir) / fmt, fmt, view=view, prefix=prefix, quality=quality)
    click.echo(f"wrote {len(done.paths)} {fmt.upper()} images to {done.out_dir} ({done.paths[0].name} .. {done.paths[-1].name}; {done.view})")


@click.command("view")
@click.argument("in_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("-o", "--out", "out_path", type=GivenPath(dir_okay=False, path_type=Path), help="The flipbook page (default: IN_DIR/flipbook/index.html; its images go beside it).")
@click.option("--format", "fmt", type=click.Choice(["jpg", "png"]), default="jpg", show_default=True, help="Image format of the flipbook's frames.")
@click.option("--open", "open_browser", is_flag=True, help="Open the page in the default web browser.")
@view_options
def view(in_dir: Path, out_path: Path | None, fmt: str, open_browser: bool, exposure: float, ocio_config: str | None,
         ocio_display: str | None, ocio_view: str | None, ocio_colorspace: str | None, prefix: str | None) -> None:
    """An HTML flipbook of IN_DIR's frames: scrubber, play/pause, frame info."""
    from motion.pipeline.telecine.export import export_images, write_flipbook

    page = out_path or Path(in_dir) / "flipbook" / "index.html"
    from motion.pipeline.telecine.movie import ViewTransform

    view = ViewTransform(exposure, ocio_config, ocio_display, ocio_view, ocio_colorspace)
    done = export_images(in_dir, page.parent / "frames", fmt, view=view, prefix=prefix)
    path = write_flipbook(done, page)
    click.echo(f"wrote {path} ({len(done.paths)} frames in {done.out_dir})")
    if open_browser:
        import webbrowser

        try:
            opened = webbrowser.open(path.resolve().as_uri())
        except webbrowser.Error:
            opened = False
        if not opened:  # a headless machine (no display, no browser): say so, never pretend
            from motion.pipeline.errors import UsageError

            raise UsageError(f"--open: no web browser can be started here (no display or none installed); the flipbook is written: open {path.resolve()} on a machine with one")


commands = [export, view]
