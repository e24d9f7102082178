"""A non-editable install renders: build the wheel, install it into a fresh environment, render.

The editable install the suite runs under maps `motion` onto the repository's folders, so it
can never notice a package missing from the wheel (`pip install .` once left out `bake` and
`shot`, and `motion render` failed with ModuleNotFoundError on every farm node installed that
way). Here the wheel is built from a copy of the sources alone, installed with `--no-deps` into a
new virtual environment that sees this environment's third-party packages (mitsuba, numpy, ...)
but not its editable `motion`, and `motion render` runs from a folder outside the repository.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from _support import REPO

pytestmark = pytest.mark.render

SOURCES = ("pyproject.toml", "setup.py", "README.md", "cli", "pipeline", "configs")


def _build_wheel(tmp_path: Path) -> Path:
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(path, src / name)
    dist = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), str(src)],
        check=True, capture_output=True, text=True, timeout=300,
    )
    (wheel,) = dist.glob("motion_farm-*.whl")
    return wheel


def test_the_wheel_holds_every_package_folder(tmp_path: Path) -> None:
    wheel = _build_wheel(tmp_path)
    names = set(zipfile.ZipFile(wheel).namelist())
    for root, package in (("pipeline", "motion/pipeline"), ("cli", "motion/cli"), ("configs", "motion/configs")):
        for init in (REPO / root).rglob("__init__.py"):
            if "__pycache__" in init.parts:
                continue
            relative = init.relative_to(REPO / root).as_posix()
            assert f"{package}/{relative}" in names, f"{root}/{relative} is not in the wheel"
    assert "motion/configs/ci-smoke.yaml" in names


def test_a_wheel_installed_into_a_fresh_environment_renders(tmp_path: Path) -> None:
    wheel = _build_wheel(tmp_path)
    env_dir = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True, timeout=120)
    python = env_dir / "bin" / "python"
    purelib = Path(subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True).stdout.strip())
    # the third-party packages of this environment, as a plain path: its .pth files (the
    # editable `motion`) are not processed from a path added this way
    (purelib / "zz_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--quiet", str(wheel)],
        check=True, capture_output=True, text=True, timeout=300,
    )
    where = subprocess.run([python, "-c", "import motion.pipeline; print(motion.pipeline.__file__)"],
                           check=True, capture_output=True, text=True, cwd=tmp_path).stdout
    assert where.startswith(str(purelib)), f"motion imported from {where}, not the installed wheel"

    work = tmp_path / "work"
    work.mkdir()
    shutil.copy2(REPO / "scenes" / "bouncing-balls.yaml", work / "shot.yaml")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run(
        [env_dir / "bin" / "motion", "render", "shot.yaml", "--preset", "ci-smoke", "-o", "out", "--no-progress"],
        capture_output=True, text=True, timeout=300, cwd=work, env=env,
    )
    assert proc.returncode == 0, proc.stderr
    assert len(list((work / "out").glob("*.exr"))) == 3, proc.stderr
