"""`motion cache clear --what kernels` removes drjit's files only: with $DRJIT_CACHE_DIR on a
folder others keep files in (a shared studio disk), their notes, their subfolders and any
file drjit does not name as it names its own stay where they are."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from motion.pipeline.cache import is_kernel_file

# names as drjit-core's io.cpp writes them (kernel, writer's temporary, sweep stamp; the
# older format without the version), and names it never writes
DRJIT = ["0ab0c683b2a8b5c7d4ed4ef1f26da2e8.llvm.v6.bin", "11d6d28cb0ecc936e8177b6c7c6aba2c.cuda.v6.bin",
         "11d6d28cb0ecc936e8177b6c7c6aba2c.llvm.v6.bin.12345.tmp", "6bc9accf1b3782c831ba12c3a2015a0c.llvm.bin",
         "6bc9accf1b3782c831ba12c3a2015a0c.llvm.bin.tmp", "sweep.stamp"]
THEIRS = ["notes.txt", "render.blend", "scene.bin", "0ab0c683.llvm.v6.bin", "0ab0c683b2a8b5c7d4ed4ef1f26da2e8.llvm.v6.bin.bak",
          "README", ".hidden", "sweep.stamp.old"]


def _motion(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "motion.cli.main", *args], capture_output=True, text=True, env=env, timeout=120)


def test_kernel_file_names_are_drjits_only() -> None:
    assert all(is_kernel_file(n) for n in DRJIT)
    assert not any(is_kernel_file(n) for n in THEIRS)


def test_clearing_kernels_in_a_shared_folder_leaves_what_is_not_drjits(tmp_path: Path) -> None:
    shared = tmp_path / "shared"
    (shared / "project").mkdir(parents=True)
    (shared / "project" / "render.blend").write_text("a colleague's scene")
    (shared / "project" / DRJIT[0]).write_text("in someone's subfolder: not ours either")
    for name in DRJIT + THEIRS:
        (shared / name).write_text("x")
    os.symlink(tmp_path / "elsewhere.bin", shared / "1234567890abcdef1234567890abcdef.llvm.v6.bin")  # a link named like ours
    (tmp_path / "elsewhere.bin").write_text("the link's target")
    env = {**os.environ, "DRJIT_CACHE_DIR": str(shared), "MOTION_CACHE_DIR": str(tmp_path / "cache")}
    before = _motion("cache", "info", env=env)
    assert before.returncode == 0, before.stderr
    assert [line.split()[1] for line in before.stdout.splitlines() if line.startswith("kernels")] == [str(len(DRJIT))]
    res = _motion("cache", "clear", "--what", "kernels", env=env)
    assert res.returncode == 0, res.stderr
    assert f"kernels: removed {len(DRJIT)} files" in res.stdout  # before: every file, notes.txt and project/render.blend too
    left = sorted(p.relative_to(shared).as_posix() for p in shared.rglob("*"))
    assert left == sorted(THEIRS + ["project", "project/render.blend", f"project/{DRJIT[0]}", "1234567890abcdef1234567890abcdef.llvm.v6.bin"])
    assert (tmp_path / "elsewhere.bin").read_text() == "the link's target"
