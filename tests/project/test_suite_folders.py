"""The suite keeps to its own folders (tests/conftest.py): it never writes into the user's
cache root (estimates, validators, kept simulations, kernels) and leaves no pytest folder in
the system's temporary folder."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.conftest import SCRATCH


def _listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file below `folder`: size and modification time."""
    out = {}
    for p in folder.rglob("*"):
        st = p.lstat()
        out[str(p.relative_to(folder))] = (st.st_size, st.st_mtime_ns)
    return out


def test_this_session_uses_its_own_cache_root_and_basetemp(tmp_path: Path) -> None:
    """The cache root and drjit's kernels are the suite's (under the repository's
    .pytest-tmp/), whatever the session was started with, in every xdist worker too; tmp_path
    lies under the session's folder, beside its cache root."""
    from motion.pipeline.cache import cache_root, kernels_dir

    assert cache_root().is_relative_to(SCRATCH) and kernels_dir().is_relative_to(SCRATCH)
    session = cache_root().parent
    assert session.name.startswith("session-") and tmp_path.is_relative_to(session)


def test_the_suites_fixtures_leave_the_users_cache_root_and_temp_folder_alone(tmp_path: Path) -> None:
    """A pytest session of the suite's own tests (renders through the CLI, which record cost
    estimates and keep validators, a kept simulation), started with MOTION_CACHE_DIR on a
    marker root, HOME on a fresh folder and TMPDIR on an empty one: afterwards the marker
    root holds exactly its marker, HOME has no cache, and TMPDIR is empty (pytest's own folder
    lived in the repository's .pytest-tmp/ and went when the session passed). Before, the
    estimates of the test scenes landed in the user's root and pytest-of-USER in /tmp."""
    marker = tmp_path / "root"
    marker.mkdir()
    (marker / "estimates.json").write_text('{"marker": true}')
    home, tmpdir = tmp_path / "home", tmp_path / "tmp"
    home.mkdir()
    tmpdir.mkdir()
    before = _listing(marker)
    env = {k: v for k, v in os.environ.items() if k not in ("DRJIT_CACHE_DIR", "XDG_CACHE_HOME", "PYTEST_XDIST_WORKER", "PYTEST_CURRENT_TEST")}
    env.update(MOTION_CACHE_DIR=str(marker), HOME=str(home), TMPDIR=str(tmpdir), MPLCONFIGDIR=str(tmp_path / "mpl"))
    tests = ["tests/bake/test_keep.py::test_second_run_reads_the_kept_simulation_and_it_is_the_same",
             "tests/cli/examples/test_smoke.py::test_cli_flag_beats_preset_beats_scene"]
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", *tests],
                         cwd=Path(__file__).resolve().parents[2], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert _listing(marker) == before
    assert not (home / ".cache").exists()
    assert not list(tmpdir.iterdir()), list(tmpdir.iterdir())


def test_every_test_file_lives_in_a_concept_folder() -> None:
    """Tests are filed by concept (docs/tests.md): no test module sits flat in tests/, and
    every folder that holds tests is a concept of pipeline/ (tests/farm/ for pipeline/farm/),
    the command's layer (tests/cli/, mirroring the same concepts) or the project's own."""
    tests = Path(__file__).resolve().parents[1]
    concepts = {"bake", "cache", "compare", "deliver", "dynamics", "farm", "identity", "motion", "output", "render", "scene", "shot", "telecine", "timeline", "examples", "project"}
    flat = sorted(p.name for p in tests.glob("test_*.py"))
    assert not flat, f"test files flat in tests/: {flat}"
    for path in tests.rglob("test_*.py"):
        parts = path.relative_to(tests).parts[:-1]
        if parts[0] == "cli":
            parts = parts[1:]
        assert not parts or parts[0] in concepts, path
