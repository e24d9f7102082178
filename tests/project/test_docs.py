"""The scene-format field reference is generated from the schema and must not drift."""

from __future__ import annotations

import subprocess
import sys

from _support import REPO


def test_scene_format_reference_is_current() -> None:
    proc = subprocess.run([sys.executable, str(REPO / "tools" / "scene_docs.py"), "--check"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_readme_starts_with_the_two_commands() -> None:
    lines = (REPO / "README.md").read_text().splitlines()
    block = lines[lines.index("```bash") + 1 : lines.index("```")]
    assert [line.split("#")[0].strip() for line in block] == ["make render", "make test"]
    ci = (REPO / ".ci" / "run").read_text()
    assert "\nmake test\n" in ci


def test_the_readmes_commands_can_be_pasted() -> None:
    """Issue 23: every line of the README's bash blocks runs as written. A `|` between two
    `motion` commands meant "or" (pasting `motion cache info | motion cache clear` cleared
    the cache); alternatives are separate lines now, and a pipe only feeds a tool."""
    import re

    text = (REPO / "README.md").read_text()
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            command = line.split("#")[0]
            for left, right in zip(command.split("|"), command.split("|")[1:]):
                assert not (left.strip().startswith("motion") and right.strip().startswith("motion")), line


def _reference_rows() -> dict[tuple[str, str], list[str]]:
    """(record, field) -> the cells of its row in the generated field reference."""
    sys.path.insert(0, str(REPO / "tools"))
    try:
        import scene_docs
    finally:
        sys.path.pop(0)
    rows: dict[tuple[str, str], list[str]] = {}
    record = ""
    for line in scene_docs.generate().splitlines():
        if line.startswith("### "):
            record = line[4:].strip()
        elif line.startswith("| `"):
            cells = [c.strip() for c in line.strip("|").split(" | ")]
            rows[(record, cells[0].strip("`"))] = cells
    return rows


def test_units_come_from_the_schema_not_from_a_fields_name() -> None:
    """A unit is the field's own: a choice or a name has none (Shutter.position was "m",
    Spring.a "m/s^2"), a planned path's start is a position (was "s"), the emitter's and the
    turntable's `rate` differ (they shared one text), a string's length is in characters
    (MorphTarget.name said "at least 1 items"); the dynamics blocks' start/stop say their clock."""
    rows = _reference_rows()
    unit = {key: cells[4] for key, cells in rows.items()}
    assert unit[("Shutter", "position")] == "" and unit[("Shutter", "angle")] == "degrees"
    assert unit[("Spring", "a")] == unit[("Spring", "b")] == "" and unit[("Spring", "stiffness")] == "N/m"
    assert unit[("PlanMotion", "start")] == "m"
    assert unit[("Turntable", "rate")] == "degrees/s" and unit[("ParticleEmitter", "rate")] == "particles/s"
    assert rows[("MorphTarget", "name")][3] == "1 to 128 characters"
    for record in ("ParticleEmitter", "DynamicsMotion", "Flock"):
        assert unit[(record, "start")] == "s" and "after the first frame" in rows[(record, "start")][5]
