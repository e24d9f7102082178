"""Command-line options (cli/options.py): numbers are finite and bounded, one usage line and exit 2 otherwise."""

from __future__ import annotations

from pathlib import Path

import pytest

from _scenes import BASE


@pytest.mark.parametrize("argv", [["render", "S", "-o", "O", "--task-timeout", "nan", "--dry-run"],
                                  ["render", "S", "-o", "O", "--task-timeout", "inf", "--dry-run"],
                                  ["telecine", "O", "-o", "O/t", "--inverse", "--tolerance", "nan"]])
def test_float_options_are_finite_and_bounded(tmp_path: Path, argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """`--task-timeout nan` or `inf` (never times out, and no claim ever stale) and
    `telecine --tolerance nan` were accepted, exit 0; now one usage line, exit 2."""
    from motion.cli.main import main as motion_main

    (tmp_path / "scene.yaml").write_text(BASE)
    argv = [str(tmp_path / "scene.yaml") if a == "S" else a.replace("O", str(tmp_path / "out")) if a.startswith("O") else a for a in argv]
    code = motion_main(argv)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and ("not a finite number" in err[0] or "not in the range" in err[0]), err
    assert not (tmp_path / "out").exists()
