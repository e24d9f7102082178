"""`motion render ... --compare REF`: after the frames, compare this job's frames with the
references in REF (the compare stage, docs/compare.md), reports into OUTPUT/compare/.
`check_compare` runs before any frame renders: a missing or damaged reference set, or an
OUTPUT/compare that cannot hold the reports, ends the command before the work."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..compare import Comparison, check_report_targets, compare_sequences, write_reports
from ..compare.frames import frame_facts
from ..compare.comparison import reference_frames
from ..errors import FrameIOError, ReferenceMismatchError


def report_folder(out_dir: str | Path) -> Path:
    """Where a render's comparison reports go: OUTPUT/compare/."""
    return Path(out_dir) / "compare"


def check_compare(ref_dir: str | Path, out_dir: str | Path, resolution: tuple[int, int] | None = None) -> None:
    """Before any work: `ref_dir` is a folder of references (a golden set's manifest read
    and every listed file checked against its digest, or a plain sequence) of the size the
    frames will have (`resolution`), and the reports can be written into OUTPUT/compare/.
    FrameIOError, ReferenceMismatchError or UsageError (exit 2) otherwise."""
    ref = Path(ref_dir)
    if not ref.is_dir():
        raise FrameIOError(f"--compare {ref}: no such folder of reference frames" if not ref.exists() else f"--compare {ref}: not a folder of reference frames")
    _, paths = reference_frames(ref, None)
    if resolution is not None:
        first = min(paths)
        size = frame_facts(paths[first]).to_dict()["resolution"]
        if list(size) != list(resolution):
            raise ReferenceMismatchError(f"--compare {ref}: the references are {size[0]}x{size[1]} ({paths[first].name}), this render makes {resolution[0]}x{resolution[1]} frames: "
                                         "frames of different sizes cannot be compared")
    folder = report_folder(out_dir)
    check_report_targets(html_dir=folder, junit=folder / "junit.xml", json_path=folder / "compare.json", what="--compare report")


def scene_part_names(scene: str | Path | None) -> dict[str, str] | None:
    """What each look part is called in the rendered scene (`material wall` for m0), for
    the notes; None when the scene cannot be read now (the notes then count parts)."""
    if not scene:
        return None
    from ..errors import MotionError
    from ..identity import part_names
    from ..scene.loader import load_scene

    try:
        return part_names(load_scene(scene, assets=False))
    except (MotionError, OSError):
        return None


def compare_render(report: dict[str, Any], ref_dir: str | Path) -> tuple[Comparison, dict[str, str]]:
    """Compare the frames this render's `report` covers with `ref_dir`; returns the
    comparison (its `notes` say how the frames were made differently) and the reports
    written (HTML, JUnit, JSON in OUTPUT/compare/)."""
    out_dir = Path(report["output_dir"])
    frames = sorted({int(row["frame"]) for row in report.get("frames", []) if "frame" in row})
    result = compare_sequences(out_dir, ref_dir, frames=frames or None, keep_maps=True, part_names=scene_part_names(report.get("scene")))
    folder = report_folder(out_dir)
    written = write_reports(result, html_dir=folder, junit=folder / "junit.xml", json_path=folder / "compare.json")
    return result, written
