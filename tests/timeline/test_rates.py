"""Frame rates as studios write them: NTSC rates written as decimals are the exact ratio."""

from __future__ import annotations

from pathlib import Path

import pytest

from _scenes import TWO_FRAMES as BASE


@pytest.mark.parametrize("written, rate", [
    ("29.97", "30000/1001"), ("59.94", "60000/1001"), ("23.976", "24000/1001"), ("23.98", "24000/1001"),
    ('"29.97"', "30000/1001"), ("119.88", "120000/1001"), ("47.952", "48000/1001"),
    ("29.9", "299/10"), ("30", "30"), ("29.971", "29971/1000"), ('"30000/1001"', "30000/1001"),
])
def test_ntsc_rates_written_as_decimals_are_the_exact_ratio(tmp_path: Path, written: str, rate: str) -> None:
    from motion.pipeline.scene import load_scene

    (tmp_path / "s.yaml").write_text(BASE.replace("fps: 24", f"fps: {written}"))
    loaded = load_scene(tmp_path / "s.yaml")
    assert loaded.scene.timeline.fps == rate  # before: 29.97 was 2997/100
