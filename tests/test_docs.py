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
