"""The compare stage: new frames against references, noise-aware (docs/compare.md).

`compare_sequences(new_dir, ref_dir)` tests each frame (stats.compare_frame: identical, equal
within noise, or different, with the regions), `bless(new_dir, golden_dir)` makes a managed
reference set, `write_reports` writes the HTML, JUnit and JSON reports.
"""

from .comparison import Comparison, FrameOutcome, compare_sequences
from .golden import Manifest, bless, read_manifest
from .report import check_report_targets, write_html, write_json, write_junit, write_reports
from .stats import FrameTest, Region, compare_frame

__all__ = ["check_report_targets", "Comparison", "FrameOutcome", "FrameTest", "Manifest", "Region", "bless", "compare_sequences", "read_manifest", "compare_frame", "write_html", "write_json", "write_junit", "write_reports"]
