"""`motion validate`: schema and semantic checks only; every problem at once."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("validate")
@click.argument("scenes", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--preset", help="Also check the scene with this preset applied.")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON on stdout (problems still go to stderr, exit 2).")
def validate(scenes: tuple[Path, ...], preset: str | None, as_json: bool) -> None:
    """Check SCENES (YAML) without rendering: one line per problem, exit 2 if any."""
    import json
    from dataclasses import asdict

    from motion.cli.main import nothing_to_finish, restore_gc
    from motion.pipeline.errors import Problem, SceneError
    from motion.pipeline.presets import load_preset, overrides_from
    from motion.pipeline.scene import load_scene
    from motion.pipeline.timeline import format_range

    nothing_to_finish()  # it only reads: its process may end without teardown (cli/main.py)
    overrides = overrides_from(load_preset(preset)[0], {}) if preset else None
    problems: list[Problem] = []
    results = []
    for n, path in enumerate(scenes):
        if n == 1:
            restore_gc()  # off while the first scene loads (cli/main.py); on for the rest
        try:
            loaded = load_scene(path, overrides)
        except SceneError as err:
            problems.extend(err.problems)
            results.append({"path": str(path), "ok": False, "problems": [asdict(p) for p in err.problems]})
            continue
        s = loaded.scene
        from motion.pipeline.scene.checks import scene_warnings

        warnings = scene_warnings(s)
        for w in warnings:
            click.echo(f"{path}: warning: {w}", err=True)
        results.append({"path": str(path), "ok": True, "name": loaded.name, "frames": [s.timeline.first, s.timeline.last], "fps": str(s.timeline.fps),
                        "objects": len(s.objects), "lights": len(s.lights), "materials": len(s.materials), "warnings": warnings})
        if not as_json:
            click.echo(
                f"{path}: ok ({loaded.name}: frames {format_range(s.timeline.first, s.timeline.last)} at {s.timeline.fps} fps, "
                f"{len(s.objects)} objects, {len(s.lights)} lights, {len(s.materials)} materials)"
            )
    if as_json:
        click.echo(json.dumps({"ok": not problems, "preset": preset, "scenes": results}, indent=2))
    if problems:
        raise SceneError(problems)


validate.start_up_only = True  # type: ignore[attr-defined]  # cli/main.py: the collector stays off while it starts
commands = [validate]
