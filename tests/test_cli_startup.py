"""What a small command imports (issue 28): `motion validate` and `motion --help` load only
the stages they use, and the lazy command table of cli/main.py names every command of
every command module, in one place."""

from __future__ import annotations

import importlib
import subprocess
import sys

from _support import REPO

HEAVY = ("mitsuba", "drjit", "scipy", "av", "matplotlib", "OpenImageIO", "PyOpenColorIO")


def _imported_after(argv: list[str]) -> set[str]:
    code = (
        "import sys\n"
        "from motion.cli.main import main\n"
        f"code = main({argv!r})\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))\n"
        "print(' '.join(sorted(m for m in sys.modules if m.startswith('motion.'))))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert res.returncode == 0, res.stderr
    tops, ours = res.stdout.strip().splitlines()[-2:]
    return set(tops.split()) | set(ours.split())


def test_validate_imports_no_renderer_farm_or_movie_stack() -> None:
    """`motion validate` of an example: no Mitsuba, drjit, scipy, PyAV, matplotlib or OCIO,
    and no module of the render, farm, shot or telecine stages (before the lazy command
    table, cli/main imported every command module: render's options pulled the farm's
    claims, the EXR writer and numpy)."""
    mods = _imported_after(["validate", str(REPO / "scenes" / "bouncing-balls.yaml")])
    assert not [m for m in HEAVY if m in mods], sorted(m for m in HEAVY if m in mods)
    stages = [m for m in mods if m.startswith(("motion.pipeline.render", "motion.pipeline.farm", "motion.pipeline.shot", "motion.pipeline.telecine", "motion.cli.render"))]
    assert not stages, stages


def test_validate_of_a_scene_without_expressions_or_array_assets_imports_no_numpy() -> None:
    """bouncing-balls has no expression to evaluate and no mesh, image or glTF to read, so
    `motion validate` never imports numpy (~0.05 s of a 0.3 s process): expressions are parsed
    without it (pipeline/expr.py builds its numpy tables on the first evaluation), limits.py
    and the expression checks import it where they use it."""
    mods = _imported_after(["validate", str(REPO / "scenes" / "bouncing-balls.yaml")])
    assert "numpy" not in mods


def test_scene_models_build_their_validators_on_first_use() -> None:
    """The ~75 scene records are declared with pydantic's defer_build: importing the schema
    builds no validator (each class used to build its own at import, then the scene's again),
    the first validation builds the one it needs."""
    code = (
        "from motion.pipeline.scene import load_scene, schema\n"
        "print(schema.Scene.__pydantic_complete__)\n"
        f"load_scene({str(REPO / 'scenes' / 'bouncing-balls.yaml')!r})\n"
        "print(schema.Scene.__pydantic_complete__)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["False", "True"]


def test_the_command_table_names_every_command_of_every_module() -> None:
    from motion.cli.main import COMMANDS, cli

    for module_name in set(COMMANDS.values()):
        module = importlib.import_module(f"motion.cli.{module_name}")
        for command in module.commands:
            assert COMMANDS.get(command.name) == module_name, f"{command.name} (motion.cli.{module_name}) is missing from cli/main.py COMMANDS"
    assert list(cli.list_commands(None)) == list(COMMANDS)  # type: ignore[arg-type]


def test_a_smoke_render_imports_no_scipy(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A ci-smoke render of a scene with keyframed rotations, a look-at camera and rigid-body
    dynamics (bouncing-balls, rendered inline) never imports scipy: rotations convert with
    numpy, the follower's k-d tree is imported only by followers (scipy.spatial cost each
    process about 0.15 s, most of a smoke job's start-up)."""
    mods = _imported_after(["-q", "render", str(REPO / "scenes" / "bouncing-balls.yaml"), "--preset", "ci-smoke", "-o", str(tmp_path), "--no-progress"])
    assert "scipy" not in mods
    assert "motion.pipeline.render.job" in mods  # it did render in this process
