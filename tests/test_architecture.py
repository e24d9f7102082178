"""The architecture's rules (docs/architecture.md): no import loop, no import from a lower
stage to a higher one, a docstring on every public definition. tools/architecture_check.py
holds the stage table and prints every violation."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location("architecture_check", ROOT / "tools" / "architecture_check.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["architecture_check"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_no_import_loop_no_upward_import_every_public_definition_documented() -> None:
    problems = _checker().problems()
    assert problems == [], "\n".join(problems)


def test_the_checker_sees_a_loop_and_an_upward_import() -> None:
    """The check is live: a loop and an upward import in a made-up graph are reported."""
    check = _checker()
    assert check.cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]
    assert check.stage("motion.pipeline.scene.loader") < check.stage("motion.pipeline.render.build")
    assert check.stage("motion.cli.main") == len(check.STAGES) - 1


def test_no_assert_in_pipeline_or_cli() -> None:
    """Checks in pipeline/ and cli/ raise: an `assert` vanishes under `python -O`."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    found = [
        f"{path.relative_to(root)}:{node.lineno}"
        for folder in ("pipeline", "cli")
        for path in sorted((root / folder).rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Assert)
    ]
    assert not found, found
