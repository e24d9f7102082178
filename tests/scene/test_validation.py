"""Validation: every malformed scene gives `FILE:LINE:COL: yaml.path: message`, exit 2,
never a traceback; all problems at once; examples validate."""

from __future__ import annotations

import copy
import random
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motion.cli.main import main
from motion.pipeline.errors import SceneError
from motion.pipeline.scene import load_scene

from _support import SCENES

BASE = """\
timeline: {fps: 24, first: 0, last: 10}
camera:
  position: [0, 1, 5]
  look_at: [0, 0, 0]
materials:
  - {name: red, type: diffuse, color: [0.8, 0.1, 0.1]}
objects:
  - name: ball
    shape: sphere
    radius: 0.5
    material: red
"""

# (id, scene text, expected yaml path, expected line, a fragment of the message)
CASES: list[tuple[str, str, str, int, str]] = [
    ("fps-zero", BASE.replace("fps: 24", "fps: 0"), "timeline.fps", 1, "must be > 0"),
    ("fps-negative", BASE.replace("fps: 24", "fps: -30"), "timeline.fps", 1, "must be > 0"),
    ("fps-garbage", BASE.replace("fps: 24", "fps: fast"), "timeline.fps", 1, "frame rate"),
    ("fps-zero-den", BASE.replace("fps: 24", "fps: '24/0'"), "timeline.fps", 1, "frame rate"),
    ("range-reversed", BASE.replace("first: 0, last: 10", "first: 10, last: 2"), "timeline", 1, "reversed"),
    ("unknown-top-key", BASE + "renderr: {spp: 4}\n", "renderr", 12, "did you mean 'render'"),
    ("unknown-camera-key", BASE.replace("  look_at", "  lookat: [0, 0, 0]\n  look_at"), "camera.lookat", 4, "did you mean 'look_at'"),
    ("camera-missing", "objects: []\n", "camera", 1, "required"),
    ("position-without-look-at", BASE.replace("  look_at: [0, 0, 0]\n", ""), "camera", 3, "go together"),
    ("position-and-transform", BASE.replace("  look_at: [0, 0, 0]\n", "  look_at: [0, 0, 0]\n  transform: {translate: [0, 0, 1]}\n"), "camera", 3, "not both"),
    ("shutter-zero", BASE.replace("  look_at: [0, 0, 0]\n", "  look_at: [0, 0, 0]\n  shutter: {angle: 0}\n"), "camera.shutter.angle", 5, "greater than 0"),
    ("shutter-over-360", BASE.replace("  look_at: [0, 0, 0]\n", "  look_at: [0, 0, 0]\n  shutter: {angle: 361}\n"), "camera.shutter.angle", 5, "less than or equal to 360"),
    ("shutter-position", BASE.replace("  look_at: [0, 0, 0]\n", "  look_at: [0, 0, 0]\n  shutter: {position: middle}\n"), "camera.shutter.position", 5, "start"),
    ("fov-180", BASE.replace("  look_at: [0, 0, 0]\n", "  look_at: [0, 0, 0]\n  fov: 180\n"), "camera.fov", 5, "less than 180"),
    ("vector-too-short", BASE.replace("position: [0, 1, 5]", "position: [0, 1]"), "camera.position[2]", 3, "too few"),
    ("vector-not-number", BASE.replace("position: [0, 1, 5]", "position: [0, one, 5]"), "camera.position[1]", 3, "number"),
    ("radius-negative", BASE.replace("radius: 0.5", "radius: -1"), "objects[0].radius", 10, "greater than 0"),
    ("unknown-shape", BASE.replace("shape: sphere", "shape: sphre"), "objects[0]", 8, "did you mean 'sphere'"),
    ("unknown-object-key", BASE.replace("    radius: 0.5\n", "    raduis: 0.5\n"), "objects[0].raduis", 10, "did you mean 'radius'"),
    ("unknown-material-ref", BASE.replace("material: red", "material: blue"), "objects[0].material", 11, "unknown material 'blue'"),
    ("unknown-material-type", BASE.replace("type: diffuse", "type: difuse"), "materials[0]", 6, "did you mean 'diffuse'"),
    ("color-negative", BASE.replace("color: [0.8, 0.1, 0.1]", "color: [-1, 0, 0]"), "materials[0].color[0]", 6, "greater than or equal to 0"),
    ("duplicate-object", BASE + "  - {name: ball, shape: cube}\n", "objects[1].name", 12, "duplicate name 'ball'"),
    ("duplicate-material", BASE.replace("materials:\n", "materials:\n  - {name: red, type: diffuse}\n"), "materials[1].name", 7, "duplicate material"),
    ("unknown-parent", BASE + "    parent: nobody\n", "objects[0].parent", 12, "unknown parent 'nobody'"),
    ("self-parent", BASE + "    parent: ball\n", "objects[0].parent", 12, "own parent"),
    (
        "parent-cycle",
        BASE + "    parent: cube\n  - {name: cube, shape: cube, parent: ball}\n",
        "objects[0].parent",
        12,
        "parent cycle",
    ),
    ("mesh-missing-file", BASE + "  - {name: m, shape: mesh, file: nowhere.obj}\n", "objects[1].file", 12, "file not found"),
    ("mesh-bad-ext", BASE + "  - {name: m, shape: mesh, file: model.fbx}\n", "objects[1].file", 12, ".obj or .ply"),
    ("envmap-missing", BASE + "lights:\n  - {type: envmap, file: sky.exr}\n", "lights[0].file", 13, "file not found"),
    ("light-unknown-type", BASE + "lights:\n  - {type: laser}\n", "lights[0]", 13, "unknown type 'laser'"),
    ("spp-zero", BASE + "render: {spp: 0}\n", "render.spp", 12, "greater than or equal to 1"),
    ("resolution-zero", BASE + "render: {resolution: [0, 10]}\n", "render.resolution[0]", 12, "greater than or equal to 1"),
    ("blur-mode", BASE + "render: {motion_blur: smear}\n", "render.motion_blur", 12, "stochastic"),
    ("output-no-hashes", BASE + "output: {filename: frame.exr}\n", "output.filename", 12, "pattern"),
    ("negative-mass", BASE + "    motion: {type: dynamics, mass: -11}\n", "objects[0].motion.mass", 12, "greater than 0"),
    ("motion-unknown-type", BASE + "    motion: {type: wobble}\n", "objects[0].motion", 12, "unknown type 'wobble'"),
    (
        "keys-not-increasing",
        BASE + "    motion:\n      type: keyframes\n      channels:\n        translate: {keys: [{time: 5, value: [0, 0, 0]}, {time: 2, value: [1, 0, 0]}]}\n",
        "objects[0].motion.channels.translate.keys",
        15,
        "increase strictly",
    ),
    (
        "unknown-channel",
        BASE + "    motion:\n      type: keyframes\n      channels:\n        wiggle: {keys: [{time: 0, value: 1}]}\n",
        "objects[0].motion.channels.wiggle",
        15,
        "unknown channel 'wiggle'",
    ),
    (
        "light-channel-of-another-light",
        BASE + "lights:\n  - {type: point, position: [0, 3, 0], motion: {type: keyframes, channels: {radiance: {keys: [{time: 0, value: 1}]}}}}\n",
        "lights[0].motion.channels.radiance",
        13,
        "unknown channel 'radiance' for a point light",
    ),
    ("rotation-form", BASE + "    transform: {rotate: {spin: 3}}\n", "objects[0].transform.rotate", 12, "a rotation needs one of"),
    ("quaternion-zero", BASE + "    transform: {rotate: {quaternion: [0, 0, 0, 0]}}\n", "objects[0].transform.rotate.quaternion", 12, "must not be zero"),
    ("spring-unknown-body", BASE + "dynamics: {springs: [{a: ball, b: ghost, stiffness: 10}]}\n", "dynamics.springs[0].a", 12, "not a dynamics body"),
    ("integrator-unknown", BASE + "dynamics: {integrator: verlet}\n", "dynamics.integrator", 12, "rk4"),
    ("nan-value", BASE.replace("radius: 0.5", "radius: .nan"), "objects[0].radius", 10, ""),
    ("yaml-syntax", BASE.replace("look_at: [0, 0, 0]", "look_at: [0, 0, 0"), "", 5, "invalid YAML"),
    ("yaml-python-tag", BASE + "evil: !!python/object/apply:os.system ['echo hacked']\n", "", 12, "tag not allowed"),
    ("yaml-duplicate-key", BASE.replace("    radius: 0.5\n", "    radius: 0.5\n    radius: 0.7\n"), "", 11, "duplicate key"),
    ("top-level-list", "- 1\n- 2\n", "<document>", 1, "expected a mapping"),
    ("empty-file", "", "<document>", 1, "empty"),
]


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return path


def test_table_is_large_enough() -> None:
    assert len(CASES) >= 30


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_malformed_scene(tmp_path: Path, case: tuple[str, str, str, int, str]) -> None:
    _, text, path, line, fragment = case
    scene = _write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    problems = info.value.problems
    match = [p for p in problems if (p.yaml_path or "<document>") == (path or p.yaml_path or "<document>") and fragment in p.message]
    assert match, f"no problem at {path!r} containing {fragment!r}; got: {[str(p) for p in problems]}"
    assert match[0].line == line, str(match[0])
    assert match[0].file == str(scene)
    assert str(match[0]).startswith(f"{scene}:{line}:")


@pytest.mark.parametrize("case", CASES[::6], ids=[c[0] for c in CASES[::6]])
def test_cli_exit_code_and_no_traceback(tmp_path: Path, case: tuple[str, str, str, int, str], capsys: pytest.CaptureFixture[str]) -> None:
    scene = _write(tmp_path, case[1])
    assert main(["validate", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert all(line.startswith(str(scene)) for line in err.strip().splitlines()), err


def test_all_problems_at_once(tmp_path: Path) -> None:
    text = BASE.replace("fps: 24", "fps: 0").replace("radius: 0.5", "radius: -1") + "render: {spp: 0}\n"
    with pytest.raises(SceneError) as info:
        load_scene(_write(tmp_path, text))
    paths = {p.yaml_path for p in info.value.problems}
    assert {"timeline.fps", "objects[0].radius", "render.spp"} <= paths


def test_python_tag_is_never_executed(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    text = BASE + f"evil: !!python/object/apply:os.system ['touch {marker}']\n"
    with pytest.raises(SceneError):
        load_scene(_write(tmp_path, text))
    assert not marker.exists()


@pytest.mark.parametrize("scene", sorted(SCENES.glob("*.yaml")), ids=lambda p: p.name)
def test_examples_validate(scene: Path) -> None:
    loaded = load_scene(scene)
    assert loaded.scene.objects


# --- fuzz: no input may produce a traceback -----------------------------------------------

yaml_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12)
)
yaml_docs = st.recursive(
    yaml_scalars,
    lambda children: st.one_of(st.lists(children, max_size=4), st.dictionaries(st.text(max_size=10), children, max_size=4)),
    max_leaves=20,
)


def _check_no_traceback(tmp_path: Path, text: str) -> None:
    scene = tmp_path / "fuzz.yaml"
    scene.write_text(text)
    try:
        load_scene(scene)
    except SceneError as err:
        assert err.problems and all(p.file == str(scene) for p in err.problems)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(doc=yaml_docs)
def test_fuzz_random_documents(tmp_path: Path, doc: Any) -> None:
    _check_no_traceback(tmp_path, yaml.safe_dump(doc))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), which=st.sampled_from(sorted(p.name for p in SCENES.glob("*.yaml"))))
def test_fuzz_mutated_examples(tmp_path: Path, data: st.DataObject, which: str) -> None:
    doc = yaml.safe_load((SCENES / which).read_text())
    doc = copy.deepcopy(doc)
    rng = random.Random(data.draw(st.integers(0, 2**32 - 1)))
    for _ in range(data.draw(st.integers(1, 4))):
        _mutate(doc, rng, data.draw(yaml_scalars))
    # keep asset paths resolvable from the copy's folder
    (tmp_path / "assets").mkdir(exist_ok=True)
    sea = SCENES / "assets" / "sea.png"
    if not (tmp_path / "assets" / "sea.png").exists():
        (tmp_path / "assets" / "sea.png").write_bytes(sea.read_bytes())
    _check_no_traceback(tmp_path, yaml.safe_dump(doc))


def _mutate(node: Any, rng: random.Random, value: Any) -> None:
    """Replace, delete or add one entry somewhere in the document tree."""
    path = []
    while isinstance(node, (dict, list)) and node and rng.random() < 0.75:
        key = rng.choice(list(node.keys())) if isinstance(node, dict) else rng.randrange(len(node))
        path.append((node, key))
        node = node[key]
    if not path:
        return
    parent, key = path[-1]
    action = rng.random()
    if action < 0.5:
        parent[key] = value
    elif action < 0.75:
        del parent[key]
    elif isinstance(parent, dict):
        parent[f"{key}_x"] = value
    else:
        parent.append(value)


def test_bad_preset_reports_every_problem_with_lines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    preset = tmp_path / "mine.yaml"
    preset.write_text("render:\n  spp: -3\n  resolutoin: [1, 2]\nframe_count: 0\n")
    scene = SCENES / "walk-cycle.yaml"
    assert main(["validate", str(scene), "--preset", str(preset)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        f"{preset}:2:8: render.spp: Input should be greater than or equal to 1 (got -3)",
        f"{preset}:3:3: render.resolutoin: unknown key 'resolutoin'; did you mean 'resolution'?",
        f"{preset}:4:14: frame_count: Input should be greater than or equal to 1 (got 0)",
    ]


def test_a_shared_asset_is_decoded_once_and_reported_where_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # two materials name one broken texture: both fields are reported, the file decoded once
    import motion.pipeline.images as images

    calls: list[Path] = []
    real = images.check_image

    def counting(path: Path) -> tuple[int, int]:
        calls.append(path)
        return real(path)

    monkeypatch.setattr(images, "check_image", counting)
    (tmp_path / "t.png").write_text("not a png")
    text = BASE.replace(
        "  - {name: red, type: diffuse, color: [0.8, 0.1, 0.1]}",
        "  - {name: red, type: diffuse, color: {file: t.png}}\n  - {name: blue, type: plastic, color: {file: t.png}}",
    )
    (tmp_path / "scene.yaml").write_text(text)
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / "scene.yaml")
    message = str(err.value)
    assert "materials[0].color.file" in message and "materials[1].color.file" in message
    assert len(calls) == 1


FOUR_MISTAKES = """\
timeline: {fps: 24, first: 0, last: 10}
camera: {position: [0, 1, 5], look_at: [0, 0, 0], fov: 40}
materials:
  - {name: red, type: diffuse, color: [0.8, 0.1, 0.1]}
objects:
  - name: ball
    shape: sphere
    radius: 0.3
    material: rde
    motion:
      type: keyframes
      interpolation: catmul-rom
      channels:
        translate:
          keys: [{time: 0, value: [0, 0, 0]}, {time: 1, value: [1, 0, 0]}]
  - name: box
    shape: cube
    sise: 1
render: {resolution: [64, 36], spp: -4}
"""


def test_every_problem_at_once_in_file_order_with_did_you_mean(tmp_path: Path) -> None:
    """Issue 23: a scene with 4 mistakes reports all 4 in one run, in line order: the
    unknown material (a semantic check) beside the schema's errors, not after they are
    fixed; a misspelt choice gets a suggestion as a misspelt key does."""
    path = tmp_path / "four.yaml"
    path.write_text(FOUR_MISTAKES)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    problems = err.value.problems
    assert [p.yaml_path for p in problems] == ["objects[0].material", "objects[0].motion.interpolation", "objects[1].sise", "render.spp"], problems
    assert [p.line for p in problems] == sorted(p.line for p in problems)
    assert "did you mean 'red'" in problems[0].message
    assert "did you mean 'catmull-rom'" in problems[1].message
    assert "did you mean 'size'" in problems[2].message


def test_an_empty_or_unlit_scene_is_warned_about(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n")
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert "warning: the scene has no objects" in err and "every frame renders black" in err


REFUSED_ITEMS = """\
timeline: {fps: 24, first: 0, last: 2}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
materials:
  - {name: red, type: diffuse, color: [0.8, 0.1, 0.1]}
  - {name: glass, type: dielectirc}
objects:
  - {name: a, shape: sphere, radius: 0.5, material: rde}
  - {name: b, shape: shpere, parent: a, material: glass, transform: {translate: [0, 1, 0]}}
  - {shape: cube, size: 1, material: blu, transform: {translate: [1.0e39, 0, 0]}}
  - {name: m, shape: mesh, parent: b, transform: {translate: [0, 1, 0]}}
  - {name: c, shape: sphere, parent: nobody}
ik: [{chain: [a, b, m], target: c}]
"""


def test_an_item_refused_whole_keeps_its_name_and_place(tmp_path: Path) -> None:
    """A list item the schema refuses whole (an unknown kind, a missing name or file) used
    to stop every semantic check (or report the items that refer to it as unknown): now
    the rest of the scene is checked in the same run, numbers included, in file order."""
    path = tmp_path / "items.yaml"
    path.write_text(REFUSED_ITEMS)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    found = [(p.line, p.yaml_path) for p in err.value.problems]
    assert found == [(5, "materials[1]"), (7, "objects[0].material"), (8, "objects[1]"), (9, "objects[2].name"), (9, "objects[2].material"),
                     (9, "objects[2].transform.translate[0]"), (10, "objects[3].file"), (11, "objects[4].parent")], err.value.problems
    text = str(err.value)
    assert "did you mean 'dielectric'" in text and "did you mean 'sphere'" in text and "unknown object" not in text
    assert "_unnamed_" not in text and "defined: a, b, m, c" in text


def test_a_scene_with_nothing_visible_or_lights_of_strength_0_is_warned_about(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 23: objects that are all hidden, or lights that all emit 0, render black (or an
    empty environment) frames as silently as an empty scene did."""
    path = tmp_path / "dark.yaml"
    path.write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nobjects: [{name: a, shape: sphere, visible: false}, {name: e, shape: empty}]\n"
                    "lights: [{type: point, position: [0, 1, 0], intensity: 0}, {type: constant, radiance: [0, 0, 0]}]\n")
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert "warning: none of the scene's 2 objects is visible" in err and "only lights of strength 0" in err


def test_choices_match_without_case_and_a_misspelt_kind_keeps_its_fields_checked(tmp_path: Path) -> None:
    """`CCD` and `HALF` got no suggestion (difflib compares case); the fields of an object
    whose shape is misspelt (`Sphere`) were never checked, so its bad interpolation showed
    only after the shape was fixed."""
    path = tmp_path / "case.yaml"
    path.write_text(REFUSED_ITEMS.replace("shape: shpere, parent: a,", "shape: Sphere, parent: a, motion: {type: keyframes, interpolation: CatmullRom, "
                                                                  "channels: {translate: {keys: [{time: 0, value: [0, 1, 0]}]}}},")
                    + "output: {pixel_type: HALF}\n")
    with pytest.raises(SceneError) as err:
        load_scene(path)
    by_path = {p.yaml_path: p.message for p in err.value.problems}
    assert "did you mean 'sphere'" in by_path["objects[1]"]
    assert "did you mean 'catmull-rom'" in by_path["objects[1].motion.interpolation"]
    assert "did you mean 'half'" in by_path["output.pixel_type"]
    assert [p.line for p in err.value.problems] == sorted(p.line for p in err.value.problems)


def _parse_both(text: str, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    """parse_yaml's outcome (data and positions, or the problems it raised) by libyaml (the
    fast path) and by PyYAML alone."""
    from motion.pipeline.scene import source

    def outcome() -> Any:
        try:
            data, smap = source.parse_yaml(text, "s.yaml")
            return data, smap.positions
        except SceneError as err:
            return [str(p) for p in err.problems]

    fast = outcome()
    with monkeypatch.context() as m:
        m.setattr(source, "_compose_fast", lambda _text: (_ for _ in ()).throw(source._Reparse()))
        slow = outcome()
    return fast, slow


HOSTILE_YAML = {
    "deep": "a: " + "[" * 70 + "]" * 70 + "\n",
    "deep-at-the-limit": "a: " + "[" * 62 + "1" + "]" * 62 + "\n",  # the scalar is the 64th level: allowed
    "one-past-the-limit": "a: " + "[" * 63 + "1" + "]" * 63 + "\n",
    "many-values": "a: [" + ", ".join(["1"] * 60) + "]\n",
    "alias-bomb": "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\nc: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n",
    "recursive-alias": "a: &a [1, *a]\n",
    "duplicate-key": "a: 1\nb: 2\na: 3\n",
    "huge-int": "a: " + "9" * 40 + "\n",
    "tab-indent": "a:\n\tb: 1\n",
    "unclosed": "a: [1, 2\nb: 3\n",
    "bad-indent": "a:\n  b: 1\n c: 2\n",
    "two-documents": "a: 1\n---\nb: 2\n",
    "control-char": "a: \x07\n",
    "tag": "a: !!python/object:os.system ls\n",
    "empty": "",
    "comment-only": "# nothing\n",
    "unicode": "name: caf\u00e9 \U0001f600\nv: [1.5e3, .inf, -0x1f, 0o17, ~, yes, 2001-12-14]\n",
    "anchors": "base: &b {x: 1, y: [1, 2]}\nother: {<<: *b, y: 3}\n",
    "block-scalars": "a: |\n  line 1\n  line 2\nb: >-\n  folded\n  text\n",
    # where the two readers differed (issue 36; the fuzz in tests/scene/test_yaml_readers.py finds more)
    "tab-after-key": "a:\t1\nb: 2\n",
    "tab-after-key-before-block": "a:\t\n  - 1\n",
    "tab-before-value": "a: \tx\n",
    "tab-in-flow": "{a:\t1}\n",
    "tab-before-colon": "a\t: 1\n",
    "tab-in-plain-scalar": "a: x\ty\n",
    "tab-at-end-of-line": "a: x\t\n",
    "tab-before-comment": "a: 1\t# c\n",
    "bom-alone-on-a-line": "a: 1\n\ufeff\nb: 2\n",
    "two-boms-at-the-start": "\ufeff\ufeffa: 1\n",
    "bom-inside-a-line": "a: x\ufeffy\nb\ufeff: 2\n",
    "non-specific-tag-empty": "material: !\n",
    "non-specific-tag-in-flow": "{a: !, b: ! x}\n",
    "non-specific-tag-on-a-sequence": "a: ! [1, 2]\n",
    "question-mark-in-a-flow-scalar": "{a: 1, b?c: 2, d? e: 3}\n",
    "tag-in-a-flow-before-a-comma": "[!x, 1]\n",
    "comment-after-a-block-indicator": "a: |#\n  text\n",
    "empty-value-in-a-flow": "{a: ,b}\n",
    "lone-surrogate": 'a: "\\ud800"\n',
    "escaped-surrogate-pair": 'a: "\\ud83d\\ude00"\n',
}


@pytest.mark.parametrize("name", sorted(HOSTILE_YAML))
def test_libyaml_and_pyyaml_read_every_document_alike(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The scene's YAML is composed by libyaml after a pass over its events bounds nesting
    and values (scene/source.py), and anything libyaml refuses is parsed again by PyYAML:
    the same data and positions, or the same located problems, as PyYAML alone. The value
    bound is lowered to 50 here so that the case stays small."""
    from motion.pipeline.scene import source

    monkeypatch.setattr(source, "MAX_YAML_NODES", 50)
    monkeypatch.setattr(source, "TOO_MANY_NODES", "more than 50 values in one file (the limit)")
    fast, slow = _parse_both(HOSTILE_YAML[name], monkeypatch)
    assert fast == slow


def test_libyaml_and_pyyaml_read_every_example_and_preset_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every example scene and built-in preset: the same data and the same position of every value."""
    root = Path(__file__).resolve().parents[2]
    files = sorted(SCENES.glob("*.yaml")) + sorted((root / "configs").glob("*.yaml"))
    assert len(files) >= 14
    for path in files:
        fast, slow = _parse_both(path.read_text(), monkeypatch)
        assert fast == slow, path.name
