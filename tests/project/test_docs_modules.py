"""Every module of pipeline/ is named where a newcomer looks for it: on its stage's line of
the stage table in docs/architecture.md, or in a module table (a markdown table whose
first cell names the file) of docs/architecture.md (paths from pipeline/) or of its
package's own doc (paths from the package)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

# the packages whose own doc keeps a module table, and that doc
PACKAGE_DOCS = {"farm": "farm.md", "dynamics": "dynamics.md", "render": "rendering.md"}


def module_files() -> list[str]:
    """Every module of pipeline/ but the packages' __init__, as a path from pipeline/."""
    base = ROOT / "pipeline"
    return sorted(str(p.relative_to(base)) for p in base.rglob("*.py") if p.name != "__init__.py" and "__pycache__" not in p.parts)


def stage_lines(text: str) -> dict[str, str]:
    """The stage table (the first fenced block) by package ('' for the lines of top-level modules)."""
    lines: dict[str, str] = {"": ""}
    for line in text.split("```")[1].splitlines():
        words = line.split()
        if not words:
            continue
        first = words[1] if words[0].isdigit() and len(words) > 1 else words[0]
        if first.endswith("/"):
            lines[first[:-1]] = line
        else:
            lines[""] += " " + line
    return lines


def table_files(text: str) -> set[str]:
    """The files the first cells of a doc's markdown tables name (`name.py`, `sub/name.py`)."""
    found: set[str] = set()
    for line in text.splitlines():
        if line.startswith("|"):
            found |= set(re.findall(r"`([\w/]+\.py)`", line.split("|")[1]))
    return found


def undocumented() -> list[str]:
    """The modules named neither on their stage's line nor in a module table."""
    architecture = (DOCS / "architecture.md").read_text()
    lines, indexed = stage_lines(architecture), table_files(architecture)
    tables = {pkg: table_files((DOCS / doc).read_text()) for pkg, doc in PACKAGE_DOCS.items()}
    missing = []
    for rel in module_files():
        package, _, inside = rel.partition("/") if "/" in rel else ("", "", rel)
        stem = Path(rel).stem
        on_line = re.search(rf"(?<![\w.]){re.escape(stem)}(?!\w)", lines.get(package, ""))
        if not (on_line or rel in indexed or inside in tables.get(package, set())):
            missing.append(rel)
    return missing


def test_every_pipeline_module_is_named_in_its_stage_doc() -> None:
    missing = undocumented()
    assert missing == [], f"name these in docs/architecture.md's stage table or a module table ({len(missing)}): {missing}"


def test_the_rule_reads_the_tables_it_claims_to() -> None:
    """The parsing is live: a stage line names a module by its stem, a table's first cell by its path."""
    text = "x\n```\n0  errors.py  limits.py\n9  farm/   frames, claims\n```\n| `telecine/cadence.py` | cadences |\n| a | `not/this.py` |\n"
    lines = stage_lines(text)
    assert "limits.py" in lines[""] and "claims" in lines["farm"]
    assert table_files(text) == {"telecine/cadence.py"}
    assert set(PACKAGE_DOCS) <= {p.split("/")[0] for p in module_files()}
