"""`motion compare NEW REF`: new frames against references, noise-aware; `--bless` makes NEW
the references (docs/compare.md). Exit 0 when every frame is identical or equal within
noise, 1 when one differs or is missing, 2 for bad input."""

from __future__ import annotations

from pathlib import Path

import click


def report_paths(report_dir: Path | None, html_dir: Path | None, junit: Path | None, json_path: Path | None) -> dict[str, Path | None]:
    """Where each report goes: `--report DIR` puts all three there (index.html, junit.xml,
    compare.json); a single flag overrides its own."""
    if report_dir is not None:
        html_dir = html_dir or report_dir
        junit = junit or report_dir / "junit.xml"
        json_path = json_path or report_dir / "compare.json"
    return {"html_dir": html_dir, "junit": junit, "json_path": json_path}


@click.command("compare")
@click.argument("new_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("ref_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--bless", is_flag=True, help="Make NEW's frames the references in REF (half floats + manifest.json) instead of comparing (with --frames: only those).")
@click.option("--allow-different-settings", is_flag=True, help="Kept for scripts: frames made differently (a material, a setting) are always compared, each difference named as a note.")
@click.option("--frames", "frames_spec", help="Only these frames: 0-23, 1,5,9 ... (default: every reference frame; with --bless every frame of NEW).")
@click.option("--prefix", help="The sequence's name in NEW when it holds several.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=Path), help="Write every report into this folder: index.html, junit.xml, compare.json.")
@click.option("--html", "html_dir", type=click.Path(file_okay=False, path_type=Path), help="Folder for the HTML report (index.html + images).")
@click.option("--junit", type=click.Path(dir_okay=False, path_type=Path), help="JUnit XML file (one test case per frame).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="JSON file with every frame's figures.")
@click.option("--flip", type=click.Choice(["different", "all", "off"]), default="different", show_default=True, help="Frames that get a FLIP score and map.")
@click.option("--workers", type=click.IntRange(min=1), help="Processes testing frames (default: up to 2).")
@click.option("-v", "--verbose", is_flag=True, help="A line per frame.")
def compare(new_dir: Path, ref_dir: Path, bless: bool, allow_different_settings: bool, frames_spec: str | None, prefix: str | None,
            report_dir: Path | None, html_dir: Path | None, junit: Path | None, json_path: Path | None, flip: str, workers: int | None, verbose: bool) -> None:
    """Compare the EXR sequence in NEW_DIR with the references in REF_DIR, frame by frame:
    identical, equal within noise, or different (where, how large, which channel).
    Exit 0 when every frame is identical or equal, 1 when one differs or is missing,
    2 for bad input or frames that cannot be compared (sizes); frames made differently (a
    material, a setting) are compared, each difference a `note:` (docs/compare.md)."""
    frames = None
    if frames_spec:
        from motion.pipeline.farm.selection import parse_frames

        frames = parse_frames(frames_spec)
    if bless:
        from motion.pipeline.compare import bless as bless_frames

        manifest = bless_frames(new_dir, ref_dir, prefix, frames)
        click.echo(f"blessed {len(manifest.frames)} frames of {new_dir} as the references in {ref_dir} ({ref_dir / 'manifest.json'})")
        return
    from motion.pipeline.compare import check_report_targets, compare_sequences, write_reports

    targets = report_paths(report_dir, html_dir, junit, json_path)
    check_report_targets(**targets)
    result = compare_sequences(new_dir, ref_dir, prefix=prefix, frames=frames, flip=flip, workers=workers, keep_maps=bool(report_dir or html_dir))  # type: ignore[arg-type]
    written = write_reports(result, **targets)
    for line in result.notes:
        click.echo(f"note: {line}", err=True)
    for f in result.frames:
        if verbose or f.failed:
            click.echo(f.message())
    click.echo(result.summary())
    for kind, path in written.items():
        click.echo(f"{kind}: {path}")
    if result.failed:
        from motion.pipeline.errors import FramesDifferError

        worst = max(result.failed, key=lambda f: (f.outcome == "different", f.max_z))
        raise FramesDifferError(f"{len(result.failed)} of {len(result.frames)} frames differ from the references in {ref_dir} (worst: {worst.message()})")


commands = [compare]
