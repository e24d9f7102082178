"""The project's own pictures, checked: every example scene's ci-smoke frames are blessed
references in tests/data/golden/<scene>/ (half floats + manifest.json), and each test here
renders them again (`motion render --preset ci-smoke --compare`) and fails when a frame
differs beyond its noise. After an intended change to an example or to the renderer,
bless them again (docs/compare.md):

    motion render scenes/X.yaml --preset ci-smoke -o /tmp/X && motion compare /tmp/X tests/data/golden/X --bless
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from farm_util import ROOT, motion

GOLDEN = ROOT / "tests" / "data" / "golden"
SCENES = sorted(p.stem for p in (ROOT / "scenes").glob("*.yaml"))


def test_every_example_has_a_small_golden_set() -> None:
    assert sorted(p.name for p in GOLDEN.iterdir() if p.is_dir()) == SCENES
    total = sum(f.stat().st_size for f in GOLDEN.rglob("*") if f.is_file())
    assert total < 512 * 1024, total  # ci-smoke resolution, half floats
    for name in SCENES:
        manifest = json.loads((GOLDEN / name / "manifest.json").read_text())
        assert manifest["resolution"] == [64, 36] and len(manifest["frames"]) == 3
        assert manifest["scene"] == f"../../../../scenes/{name}.yaml"


@pytest.mark.render
@pytest.mark.parametrize("name", SCENES)
def test_example_matches_its_golden_frames(name: str, tmp_path: Path) -> None:
    res = motion("render", ROOT / "scenes" / f"{name}.yaml", "--preset", "ci-smoke", "-o", tmp_path / name, "--no-progress",
                 "--compare", GOLDEN / name, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "PASS: 3 frames" in res.stderr, res.stderr
    assert (tmp_path / name / "compare" / "index.html").is_file() and (tmp_path / name / "compare" / "junit.xml").is_file()
