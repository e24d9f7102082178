"""What a small command imports (issue 28): `motion validate` and `motion --help` load only
the stages they use, and the lazy command table of cli/main.py names every command of
every command module, in one place."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import ValidationError

from _support import REPO

HEAVY = ("mitsuba", "drjit", "scipy", "av", "matplotlib", "OpenImageIO", "PyOpenColorIO")


def _imported_after(argv: list[str], env: dict[str, str] | None = None) -> set[str]:
    code = (
        "import sys\n"
        "from motion.cli.main import main\n"
        f"code = main({argv!r})\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))\n"
        "print(' '.join(sorted(sys.modules)))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO, env={**os.environ, **(env or {})})
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


def _in_process(code: str, cache: Path) -> list[str]:
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO, env={**os.environ, "MOTION_CACHE_DIR": str(cache)})
    assert res.returncode == 0, res.stderr
    return res.stdout.split()


def test_scene_models_build_their_validators_on_first_use_and_the_next_process_loads_it(tmp_path: Path) -> None:
    """The ~75 scene records are declared with pydantic's defer_build: importing the schema
    builds no validator (each class used to build its own at import, then the scene's again;
    defaults such as `transform: Transform = Transform()` built Transform's). The first
    validation builds the scene's and keeps it in the cache root; the next process loads it
    and builds none (pipeline/scene/compiled.py)."""
    code = (
        "from motion.pipeline.scene import load_scene, schema, types\n"
        "print(schema.Scene.__pydantic_complete__, types.Transform.__pydantic_complete__)\n"
        f"load_scene({str(REPO / 'scenes' / 'bouncing-balls.yaml')!r})\n"
        "print(schema.Scene.__pydantic_complete__)\n"
    )
    assert _in_process(code, tmp_path) == ["False", "False", "True"]
    assert len(list((tmp_path / "validation").glob("Scene-*.pickle"))) == 1
    assert _in_process(code, tmp_path) == ["False", "False", "False"]


def test_the_kept_scene_validator_gives_the_same_records_and_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Loaded from its entry, the validator makes the same records of every example as
    `Scene.model_validate` (the `imports:` lists as `ImportList.model_validate`), and the
    same errors of a scene with many (errors are what users read)."""
    from motion.pipeline.scene import compiled
    from motion.pipeline.scene.imports.spec import ImportList
    from motion.pipeline.scene.schema import Scene
    from motion.pipeline.scene.source import parse_yaml

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "_validators", {})
    entry = compiled.entry_path(Scene)
    compiled.kept_validator(Scene)
    compiled.kept_validator(ImportList)
    kept = compiled._load(entry)
    assert kept is not None and kept is not Scene.__pydantic_validator__
    for path in sorted((REPO / "scenes").glob("*.yaml")):
        data, _ = parse_yaml(path.read_text(), str(path))
        if "imports" in data:  # validated as the import list, then expanded before the scene is
            imports = {"imports": data["imports"]}
            assert compiled._load(compiled.entry_path(ImportList)).validate_python(imports) == ImportList.model_validate(imports), path.name  # type: ignore[union-attr]
            continue
        assert kept.validate_python(data) == Scene.model_validate(data), path.name
    bad = {"camera": {"fov": -1, "position": [0, 0, "x"]}, "lights": [{"type": "pont"}, {"type": "sun", "direction": [0, 0, 0], "irradiance": float("nan")}],
           "objects": [{"name": "a", "shape": "sphere", "radius": 0, "transform": {"rotate": {"quaternion": [0, 0, 0, 0]}}}], "timeline": {"first": 5, "last": 1}}
    with pytest.raises(ValidationError) as ours:
        kept.validate_python(bad)
    with pytest.raises(ValidationError) as theirs:
        Scene.model_validate(bad)
    assert ours.value.errors(include_url=False, include_context=False) == theirs.value.errors(include_url=False, include_context=False)
    assert len(ours.value.errors()) >= 5


def test_a_scene_validator_entry_is_used_only_when_whole_and_current(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An entry whose sources changed (size or modification time), cut short, or naming a
    record the code no longer has, is not used: the validator is made again and the entry
    replaced."""
    import pickle

    from motion.pipeline.scene import compiled
    from motion.pipeline.scene.schema import Scene

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "_validators", {})
    entry = compiled.entry_path(Scene)
    compiled.kept_validator(Scene)
    whole = entry.read_bytes()
    assert compiled._load(entry) is not None
    with open(entry, "rb") as fh:
        sources = pickle.load(fh)
    assert any(s[0].endswith("scene/schema.py") for s in sources) and any(s[0].endswith("scene/types.py") for s in sources)

    stale = [(f, size, mtime + 1 if f.endswith("types.py") else mtime) for f, size, mtime in sources]
    entry.write_bytes(pickle.dumps(stale) + whole[len(pickle.dumps(sources)):])
    assert compiled._load(entry) is None
    entry.write_bytes(whole[: len(whole) // 2])
    assert compiled._load(entry) is None
    entry.write_bytes(whole.replace(b"RenderSettings", b"RenderSettingz"))
    assert compiled._load(entry) is None
    monkeypatch.setattr(compiled, "_validators", {})
    compiled.kept_validator(Scene)  # made again, and kept
    assert entry.read_bytes() == whole


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
    assert "motion.pipeline.render.worker.job" in mods  # it did render in this process


def test_record_defaults_made_without_validation_equal_the_validated_ones() -> None:
    """A field default written `Record.default()` (made by `model_construct`, so that
    importing the schema builds no validator) equals `Record()`, validators and all, for
    every record of the scene format."""
    from pydantic import BaseModel

    from motion.pipeline.scene import dynamics_schema, motion_schema, schema, types
    from motion.pipeline.scene.imports import spec

    records = {cls for module in (schema, types, spec, motion_schema, dynamics_schema) for cls in vars(module).values() if isinstance(cls, type) and issubclass(cls, types.Model)}
    checked = 0
    for cls in records:
        for name, field in cls.model_fields.items():
            if isinstance(field.default, BaseModel):
                assert field.default == type(field.default)(), f"{cls.__name__}.{name}"
                checked += 1
    assert checked >= 12


def test_an_asset_whose_bytes_passed_is_not_decoded_again_and_a_changed_or_failing_one_is(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """What validation keeps of assets (scene/checked.py): a texture that decoded is not
    decoded by the next load; the same name with other bytes is; a damaged file is decoded
    and refused every time (a failure is never kept); other checking code misses."""
    from PIL import Image

    import motion.pipeline.images as images
    from motion.pipeline.errors import SceneError
    from motion.pipeline.scene import checked, load_scene

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    tex = tmp_path / "tex.png"
    Image.new("RGB", (4, 4), (200, 10, 10)).save(tex)
    scene = tmp_path / "s.yaml"
    scene.write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nmaterials: [{name: m, type: diffuse, color: {file: tex.png}}]\n"
                     "objects: [{name: a, shape: sphere, material: m}]\nlights: [{type: constant, radiance: 1}]\n")
    decoded: list[Path] = []
    real = images.check_image
    monkeypatch.setattr(images, "check_image", lambda p: decoded.append(p) or real(p))
    load_scene(scene)
    load_scene(scene)
    assert len(decoded) == 1
    Image.new("RGB", (4, 4), (10, 200, 10)).save(tex)  # repainted under the same name
    load_scene(scene)
    assert len(decoded) == 2
    tex.write_bytes(tex.read_bytes()[:40])  # cut short
    for _ in range(2):
        with pytest.raises(SceneError, match="tex.png"):
            load_scene(scene)
    assert len(decoded) == 4
    Image.new("RGB", (4, 4), (10, 200, 10)).save(tex)  # the bytes that passed before: kept
    load_scene(scene)
    assert len(decoded) == 4
    monkeypatch.setattr(checked.STORE, "_version", "another checker")
    load_scene(scene)
    assert len(decoded) == 5


def test_a_kept_gltf_import_is_validated_without_its_reader(tmp_path: Path) -> None:
    """The second `motion validate` of the walker reads its import's kept records and
    never imports the glTF reader, pygltflib or numpy (imports/memo.py)."""
    env = {"MOTION_CACHE_DIR": str(tmp_path)}
    walker = str(REPO / "scenes" / "walker.yaml")
    first = _imported_after(["validate", walker], env)
    assert "motion.pipeline.scene.imports.gltf" in first
    again = _imported_after(["validate", walker], env)
    assert not {"numpy", "pygltflib", "motion.pipeline.scene.imports.gltf"} & again


def test_validate_ends_with_its_output_whole_and_leaves_an_in_process_caller_as_it_was() -> None:
    """`motion validate` ends its process without the interpreter's teardown (cli/main.py):
    its output, here the JSON of every example through a pipe, is whole. Called in-process
    with arguments, `main` leaves the garbage collector as it found it, on or off."""
    import gc
    import json

    from _support import run_motion

    from motion.cli.main import main

    scenes = sorted(str(p) for p in (REPO / "scenes").glob("*.yaml"))
    proc = run_motion("validate", "--json", *scenes)
    assert proc.returncode == 0, proc.stderr
    assert [s["ok"] for s in json.loads(proc.stdout)["scenes"]] == [True] * len(scenes)
    one = str(REPO / "scenes" / "bouncing-balls.yaml")
    assert gc.isenabled()
    assert main(["validate", one]) == 0 and gc.isenabled()
    assert main(["cache", "key"]) == 0 and gc.isenabled()
    gc.disable()
    try:
        assert main(["validate", one]) == 0 and not gc.isenabled()
    finally:
        gc.enable()


def test_kept_asset_passes_are_held_to_a_bound(tmp_path: Path) -> None:
    """Each of the 256 folders of kept asset passes holds at most SHARD_CAP of them, by the
    stores' one eviction policy: over the cap, the least recently used go until it holds the
    cap (one pass per texture version a machine has seen would otherwise grow without end);
    temporary files are left to their writers."""
    import os

    from motion.pipeline.cache import hold_to_cap
    from motion.pipeline.scene.checked import SHARD_CAP

    assert SHARD_CAP == 1024
    for i in range(5):
        (tmp_path / f"pass{i}").write_bytes(b"")
        os.utime(tmp_path / f"pass{i}", ns=(i * 10**9, i * 10**9))
    (tmp_path / ".pass.tmp").write_bytes(b"")
    hold_to_cap(tmp_path, None, 5)
    assert len(list(tmp_path.iterdir())) == 6
    hold_to_cap(tmp_path, None, 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".pass.tmp", "pass3", "pass4"]


@pytest.mark.parametrize("scene", ["bouncing-balls", "cannonball-splash"])
def test_a_rerun_that_renders_nothing_imports_no_numpy_openexr_or_bake(tmp_path: Path, scene: str) -> None:
    """A rerun of an example's ci-smoke job whose frames are all kept (their identities
    kept, identity/kept.py; their files unchanged since a rerun decoded them whole) imports neither
    numpy nor the OpenEXR bindings, nor the bake's, the motion stage's or the movies'
    modules: each frame's header is read from its bytes (frame_output.plain_meta), and the
    packages import their modules on first use (about 0.3 s of a 0.8 s rerun).
    cannonball-splash's output.deliver makes a contact sheet: up to date, it is known so
    from the manifest's record of its frames' files, the view's kept description and the
    encoders' kept probe, without OpenColorIO, PyAV or a frame opened (shot/deliver.py)."""
    env = {"MOTION_CACHE_DIR": str(tmp_path / "cache")}
    argv = ["-q", "render", str(REPO / "scenes" / f"{scene}.yaml"), "--preset", "ci-smoke", "-o", str(tmp_path / "out"), "--no-progress"]
    first = _imported_after(argv, env)
    assert "motion.pipeline.render.worker.job" in first and "numpy" in first  # it rendered
    assert "OpenEXR" in _imported_after(argv, env)  # the first rerun decodes each frame once (then known whole)
    again = _imported_after(argv, env)
    # pydantic's plugin loader (and importlib.metadata under it) come only with a validator
    # built in this process: the preset's are kept like the scene's (scene/compiled.py)
    heavy = {"numpy", "OpenEXR", *HEAVY, "motion.pipeline.bake.baking", "motion.pipeline.motion", "motion.pipeline.telecine",
             "pydantic.plugin._loader", "importlib.metadata"} & again
    assert not heavy, sorted(heavy)
    report = json.loads((tmp_path / "out" / "render-report.json").read_text())
    assert report["totals"]["skipped"] == 3
    if scene == "cannonball-splash":
        assert report["deliverables"]["status"] == {"contact": "up to date"}
