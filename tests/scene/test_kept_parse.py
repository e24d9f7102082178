"""A scene file's parse is kept between processes (scene/source.py: parse_kept): the same
bytes are read back from their JSON with the source map deferred, and every problem is
found and located exactly as a fresh parse finds it (issue 44: a 1,000-mover shot spent
0.7 s of each worker's first frame parsing the scene the main process had just parsed)."""

from __future__ import annotations

from pathlib import Path

import pytest

from motion.pipeline.cache import STORES
from motion.pipeline.errors import SceneError
from motion.pipeline.scene import load_scene
from motion.pipeline.scene.source import DeferredSourceMap

from tests.scene.test_validation import BASE, CASES


@pytest.fixture
def root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


def _problems(path: Path) -> list[str]:
    with pytest.raises(SceneError) as err:
        load_scene(path, assets=False)
    return [str(p) for p in err.value.problems]


def test_a_kept_parse_gives_the_same_scene_and_its_positions_on_demand(root: Path) -> None:
    path = root / "s.yaml"
    path.write_text(BASE)
    fresh = load_scene(path, assets=False)
    hits = STORES["parsed"].stats["hits"]
    kept = load_scene(path, assets=False)
    assert STORES["parsed"].stats["hits"] == hits + 1 and isinstance(kept.source, DeferredSourceMap)
    assert kept.scene == fresh.scene and kept.data == fresh.data
    assert kept.source.problem(("objects", 0, "radius"), "x") == fresh.source.problem(("objects", 0, "radius"), "x")
    assert kept.source.positions == fresh.source.positions
    # another file of the same bytes names its own file in its problems
    other = root / "t.yaml"
    other.write_text(BASE)
    assert load_scene(other, assets=False).source.problem(("camera",), "x").file == str(other)


@pytest.mark.parametrize("case", CASES[:12] + [c for c in CASES if c[0] in ("unknown-material-ref", "duplicate-object")], ids=lambda c: c[0])
def test_every_problem_of_a_kept_parse_is_located_as_a_fresh_one(root: Path, case: tuple[str, str, str, int, str]) -> None:
    """The scene's schema and semantic problems come after the parse, so a file that has
    them is kept parsed; read back, each is found and located exactly as before."""
    _, text, _, _, _ = case
    path = root / "bad.yaml"
    path.write_text(text)
    first = _problems(path)
    hits = STORES["parsed"].stats["hits"]
    assert _problems(path) == first
    assert STORES["parsed"].stats["hits"] == hits + 1  # (the second read the kept parse)


def test_a_document_json_cannot_hold_or_that_does_not_parse_is_not_kept(root: Path) -> None:
    dated = root / "dated.yaml"
    dated.write_text(BASE.replace("timeline:", "made: 2026-11-28\ntimeline:"))
    first = _problems(dated)  # a date is no scene field; the problem is named either way
    assert _problems(dated) == first
    broken = root / "broken.yaml"
    broken.write_text(BASE + "  - {name: [\n")
    assert _problems(broken) == _problems(broken)
    assert not list((root / "cache").rglob("*.json"))


def test_a_damaged_kept_parse_is_parsed_again(root: Path) -> None:
    path = root / "s.yaml"
    path.write_text(BASE)
    fresh = load_scene(path, assets=False)
    (entry,) = list((root / "cache").rglob("*.json"))
    entry.write_text("[1, 2")  # not JSON (a half-written file from another tool)
    again = load_scene(path, assets=False)
    assert again.scene == fresh.scene and not isinstance(again.source, DeferredSourceMap)
    entry.write_text("[1, 2]")  # JSON, but not a document of ours
    assert load_scene(path, assets=False).scene == fresh.scene
