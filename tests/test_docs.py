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
