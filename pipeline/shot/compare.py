"""`motion render ... --compare REF`: after the frames, compare this job's frames with the
references in REF (the compare stage, docs/compare.md), reports into OUTPUT/compare/."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..compare import Comparison, compare_sequences, write_reports


def compare_render(report: dict[str, Any], ref_dir: str | Path, *, allow_different_settings: bool = False) -> tuple[Comparison, dict[str, str]]:
    """Compare the frames this render's `report` covers with `ref_dir`; returns the
    comparison and the reports written (HTML, JUnit, JSON in OUTPUT/compare/)."""
    out_dir = Path(report["output_dir"])
    frames = sorted({int(row["frame"]) for row in report.get("frames", []) if "frame" in row})
    result = compare_sequences(out_dir, ref_dir, frames=frames or None, allow_different_settings=allow_different_settings, keep_maps=True)
    folder = out_dir / "compare"
    written = write_reports(result, html_dir=folder, junit=folder / "junit.xml", json_path=folder / "compare.json")
    return result, written
