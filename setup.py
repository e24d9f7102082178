"""Package discovery for the installed name `motion` (the rest of the metadata is pyproject.toml).

The repository keeps the stages in top-level folders (`pipeline/`, `cli/`, `configs/`); the
installed package maps each onto `motion.<name>`. Every package under those folders is found
here from the folders themselves, so a new subpackage can never be left out of a wheel
(a hand-kept list in pyproject.toml once left out `bake` and `shot`: `pip install .` could not
render). `tests/cli/test_wheel.py` builds the wheel, installs it into a fresh environment and renders.
"""

from setuptools import find_packages, setup

# installed package -> folder in the repository
ROOTS = {"motion.cli": "cli", "motion.pipeline": "pipeline", "motion.configs": "configs"}

packages = [
    name
    for package, folder in ROOTS.items()
    for name in [package, *(f"{package}.{sub}" for sub in find_packages(where=folder))]
]

setup(package_dir=ROOTS, packages=packages)
