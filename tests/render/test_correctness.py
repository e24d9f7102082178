"""Our motion_path integrator against Mitsuba's own `path` on static scenes: diffuse,
rough and smooth conductor, dielectric, plastic; area and environment lighting. Judged
against the noise floor: |ours - ref| must be no larger than |ref(seed a) - ref(seed b)|
allows. Objects are rendered both in the static set and as movers (rest-frame scenes)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from _light_scenes import BALL, ball_shape, light_scene_yaml, reference_scene
from _render_support import activate, load

pytestmark = pytest.mark.render

SPP = 128


def _scene(tmp_path: Path, moving: bool) -> str:
    from motion.pipeline.frame_output import write_frame

    # a small lat-long environment: a bright band over a dim sky
    env = np.full((16, 32, 3), 0.2, np.float32)
    env[4:7] = [2.0, 1.6, 1.2]
    write_frame(tmp_path / "env.exr", env, pixel_type="float")
    # a tiny keyed motion that holds still: routes an object through the mover path
    motion = "motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: %s}, {time: 10, value: %s}]}}}" if moving else ""

    def obj(name: str, mat: str, x: float) -> str:
        pos = f"[{x}, 0.35, 0]"
        m = (motion % (pos, pos)) if moving else ""
        return f"  - {{name: {name}, shape: sphere, radius: 0.35, material: {mat}, transform: {{translate: {pos}}}, {m}}}\n".replace(", }", "}")

    return (
        """
timeline: {fps: 24, first: 0, last: 0}
camera: {position: [0, 1.2, 4], look_at: [0, 0.3, 0], fov: 45}
lights:
  - {type: envmap, file: env.exr, scale: 1.0}
materials:
  - {name: matte, type: diffuse, color: [0.7, 0.3, 0.2]}
  - {name: gold, type: conductor, preset: Au, roughness: 0.3}
  - {name: mirror, type: conductor, preset: none}
  - {name: glass, type: dielectric, ior: 1.5}
  - {name: coat, type: plastic, color: [0.1, 0.3, 0.7], roughness: 0.2}
  - {name: floor, type: diffuse, color: 0.5}
objects:
  - {name: floor, shape: rectangle, width: 8, height: 8, material: floor, transform: {rotate: {euler: [-90, 0, 0]}}}
  - {name: lamp, shape: rectangle, width: 1, height: 1, emission: {radiance: 6.0}, transform: {translate: [0, 2.5, 0], rotate: {euler: [90, 0, 0]}}}
"""
        + obj("a", "matte", -1.6)
        + obj("b", "gold", -0.8)
        + obj("c", "mirror", 0.0)
        + obj("d", "glass", 0.8)
        + obj("e", "coat", 1.6)
        + f"render: {{resolution: [64, 48], spp: {SPP}, max_depth: 6, rr_depth: 6, motion_blur: off}}\n"
    )


@pytest.mark.parametrize("moving", [False, True], ids=["static-set", "rest-frame-movers"])
def test_agrees_with_mitsuba_path(tmp_path: Path, moving: bool) -> None:
    activate()
    import mitsuba as mi

    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.render.poses.stacked import stack_frame
    from motion.pipeline.bake import evaluate_frames

    loaded = load(tmp_path, _scene(tmp_path, moving))
    (fi,) = evaluate_frames(loaded, [0])
    renderer = FrameRenderer(loaded)
    if moving:
        assert set(renderer.mover_names) == {"a", "b", "c", "d", "e"}
    ours = np.stack([renderer.render(fi)[0][..., :3] for _ in range(1)])[0]
    reference = renderer._full_scene(stack_frame(fi), None)  # the same records, Mitsuba's `path`
    ref_a = np.array(mi.render(reference, seed=11, spp=SPP))[..., :3]
    ref_b = np.array(mi.render(reference, seed=12, spp=SPP))[..., :3]
    assert np.isfinite(ours).all()
    floor = np.abs(ref_a - ref_b).mean()
    assert np.abs(ours - ref_a).mean() < 1.3 * floor, (np.abs(ours - ref_a).mean(), floor)
    assert ours.mean() == pytest.approx(ref_a.mean(), rel=0.02)
    # and it is a real picture, not two blank images agreeing
    assert ours.std() > 0.05


# --- every light the format offers, against Mitsuba's `path` with hand-written emitters ------
#
# The reference scene is written here directly in Mitsuba's terms (emitter dictionaries from
# the YAML values, by hand), never through our light builder: a light that we place wrongly
# cannot agree with itself. Frames 0 (cold) and 2 (warm, one renderer) are both checked.

LIGHT_SPP = 64
LIGHT_RES = (40, 30)


def _light_scene(lights: str, extra_objects: str = "", blur: str = "off") -> str:
    return light_scene_yaml(lights, BALL + extra_objects, resolution=LIGHT_RES, spp=LIGHT_SPP, blur=blur)


def _T() -> Any:
    import mitsuba as mi

    return mi.ScalarTransform4f()


def _reference_scene(emitters: dict[str, Any], shapes: dict[str, Any] | None = None, spp: int = LIGHT_SPP) -> Any:
    """The test scene in Mitsuba's own terms (with the ball), lit by `emitters`."""
    import mitsuba as mi

    return reference_scene(mi, emitters, {**ball_shape(mi), **(shapes or {})}, resolution=LIGHT_RES, spp=spp)


def _spot_to_world(origin: list[float], target: list[float]) -> Any:
    up = [0, 0, 1] if abs(origin[0] - target[0]) + abs(origin[2] - target[2]) < 1e-9 else [0, 1, 0]
    return _T().look_at(origin=origin, target=target, up=up)


def _env_image(tmp_path: Path) -> None:
    from motion.pipeline.frame_output import write_frame

    env = np.full((16, 32, 3), 0.15, np.float32)
    env[3:7, 4:10] = [4.0, 3.2, 2.4]  # a bright patch at one azimuth: rotation matters
    write_frame(tmp_path / "sky.exr", env, pixel_type="float")


_KEYED = "motion: {type: keyframes, interpolation: linear, channels: {%s: {keys: [{time: 0, value: %s}, {time: 2, value: %s}]}}}"
_LAMP = {"type": "rectangle", "emitter": {"type": "area", "radiance": 8.0}, "bsdf": {"type": "diffuse", "reflectance": 0.0}}


def _lamp_yaml(motion: str = "") -> str:
    return (
        "  - {name: lamp, shape: rectangle, width: 1, height: 1, emission: {radiance: 8.0}, material: black, "
        "transform: {translate: [-0.5, 2.0, 0], rotate: {euler: [90, 0, 0]}}" + (f", {motion}" if motion else "") + "}\n"
    )


def _lamp_ref(x: float) -> dict[str, Any]:
    return {"lamp": {**_LAMP, "to_world": _T().translate([x, 2.0, 0]) @ _T().rotate([1, 0, 0], 90) @ _T().scale([0.5, 0.5, 1])}}


SLIDE = "slide.exr"  # the projector's image, written into the test's folder by _slide_image


def _slide_image(folder: Path) -> None:
    from motion.pipeline.frame_output import write_frame

    img = np.full((12, 16, 3), 0.3, np.float32)
    img[2:6, 2:7] = [3.0, 2.0, 1.0]  # a bright patch in one corner: a flip or a roll of the slide shows
    write_frame(folder / SLIDE, img, pixel_type="float")


def _projector_ref(origin: list[float], target: list[float], scale: float) -> dict[str, Any]:
    """Mitsuba's `projector` by hand; the image's path is filled in by the test ("@slide")."""
    return {"type": "projector", "to_world": _spot_to_world(origin, target), "irradiance": {"type": "bitmap", "filename": "@slide"}, "fov": 40.0, "scale": scale}


def _fill_slide(d: Any, path: str) -> Any:
    if isinstance(d, dict):
        return {k: _fill_slide(v, path) for k, v in d.items()}
    return path if d == "@slide" else d


# id -> (lights YAML, extra objects YAML, reference at f = frame / 2 in [0, 1]: (emitters, shapes))
_MANY = [[-2 + 0.25 * k, 3.0, ((k % 3) - 1) * 0.8] for k in range(17)]  # 17 lamps: past lights.EACH_MAX


LIGHT_CASES: dict[str, tuple[str, str, Any]] = {
    "directional-down": (
        "  - {type: directional, direction: [0, -1, 0], irradiance: 2.5}",
        "",
        lambda f: ({"sun": {"type": "directional", "direction": [0, -1, 0], "irradiance": 2.5}}, {}),
    ),
    "directional-examples-sun": (
        "  - {type: directional, direction: [-0.4, -1.0, -0.3], irradiance: 2.5}",
        "",
        lambda f: ({"sun": {"type": "directional", "direction": [-0.4, -1.0, -0.3], "irradiance": 2.5}}, {}),
    ),
    "point": (
        "  - {type: point, position: [0, 3, 0], intensity: 10}",
        "",
        lambda f: ({"bulb": {"type": "point", "position": [0, 3, 0], "intensity": 10.0}}, {}),
    ),
    "spot-down": (
        "  - {type: spot, position: [0, 3, 0], look_at: [0, 0, 0], intensity: 30}",
        "",
        lambda f: ({"spot": {"type": "spot", "to_world": _spot_to_world([0, 3, 0], [0, 0, 0]), "intensity": 30.0}}, {}),
    ),
    "spot-cutoff-beam": (
        "  - {type: spot, position: [1.5, 3, 1], look_at: [0, 0, 0], intensity: [30, 25, 20], cutoff_angle: 35, beam_width: 15}",
        "",
        lambda f: (
            {
                "spot": {
                    "type": "spot",
                    "to_world": _spot_to_world([1.5, 3, 1], [0, 0, 0]),
                    "intensity": {"type": "rgb", "value": [30, 25, 20]},
                    "cutoff_angle": 35.0,
                    "beam_width": 15.0,
                }
            },
            {},
        ),
    ),
    "constant": ("  - {type: constant, radiance: 0.6}", "", lambda f: ({"sky": {"type": "constant", "radiance": 0.6}}, {})),
    "envmap-rotated": (
        "  - {type: envmap, file: sky.exr, scale: 1.5, transform: {rotate: {euler: [0, 90, 0]}}}",
        "",
        "envmap",  # built in the test (needs the image's path)
    ),
    "envmap-smooth-and-sun": (
        "  - {type: envmap, file: smooth.exr}\n  - {type: directional, direction: [0.5, -1.0, 0.2], irradiance: 1.0}",
        "",
        "envmap-smooth",  # built in the test (needs the image's path); reached by BSDF sampling only
    ),
    "area-static": (
        "  - {type: constant, radiance: 0.05}",
        "  - {name: lamp, shape: rectangle, width: 1, height: 1, emission: {radiance: 8.0}, material: black, transform: {translate: [-0.5, 2.0, 0], rotate: {euler: [90, 0, 0]}}}\n",
        lambda f: ({"sky": {"type": "constant", "radiance": 0.05}}, _lamp_ref(-0.5)),
    ),
    "area-on-mover": (
        "  - {type: constant, radiance: 0.05}",
        _lamp_yaml(_KEYED % ("translate", "[-1.5, 2.0, 0]", "[0.5, 2.0, 0]")),
        lambda f: ({"sky": {"type": "constant", "radiance": 0.05}}, _lamp_ref(-1.5 + 2 * f)),
    ),
    "point-keyed": (
        "  - {type: point, position: [0, 3, 0], intensity: 10, " + _KEYED % ("translate", "[-1.5, 3, 0]", "[1.5, 3, 0]") + "}",
        "",
        lambda f: ({"bulb": {"type": "point", "position": [-1.5 + 3 * f, 3, 0], "intensity": 10.0}}, {}),
    ),
    "spot-keyed-rotation": (
        "  - {type: spot, position: [0, 3, 0], look_at: [0, 0, 0], intensity: 30, cutoff_angle: 30, "
        + _KEYED % ("rotate", "[90, 0, 0]", "[60, 0, 0]")
        + "}",
        "",
        lambda f: ({"spot": {"type": "spot", "to_world": _T().translate([0, 3, 0]) @ _T().rotate([1, 0, 0], 90 - 30 * f), "intensity": 30.0, "cutoff_angle": 30.0}}, {}),
    ),
    "directional-keyed": (
        "  - {type: directional, direction: [0, -1, 0], irradiance: 2.5, " + _KEYED % ("rotate", "[90, 0, 0]", "[120, 0, 0]") + "}",
        "",
        lambda f: (
            {"sun": {"type": "directional", "direction": [0, -np.sin(np.radians(90 + 30 * f)), np.cos(np.radians(90 + 30 * f))], "irradiance": 2.5}},
            {},
        ),
    ),
    "spot-parented": (
        "  - {type: spot, parent: rig, position: [0, 3, 0], look_at: [1, 0, 0], intensity: 30, cutoff_angle: 30}",
        "  - {name: rig, shape: empty, transform: {translate: [1, 0, 0.5], rotate: {euler: [0, 30, 0]}}}\n",
        lambda f: (
            {
                "spot": {
                    "type": "spot",
                    "to_world": _spot_to_world([1, 3, 0.5], [1 + np.cos(np.radians(30)), 0, 0.5 - np.sin(np.radians(30))]),
                    "intensity": 30.0,
                    "cutoff_angle": 30.0,
                }
            },
            {},
        ),
    ),
    # several lights at once: the static ones chosen by contribution (render/kernel/lights.py),
    # the constant sky reached by BSDF sampling only, moving lights and lamps beside them
    "sun-sky-lamp": (
        "  - {type: constant, radiance: 0.3}\n  - {type: directional, direction: [-0.4, -1.0, -0.3], irradiance: 2.5}",
        _lamp_yaml(),
        lambda f: ({"sky": {"type": "constant", "radiance": 0.3}, "sun": {"type": "directional", "direction": [-0.4, -1.0, -0.3], "irradiance": 2.5}}, _lamp_ref(-0.5)),
    ),
    "point-sun-sky": (
        "  - {type: constant, radiance: 0.2}\n  - {type: directional, direction: [0.5, -1.0, 0.2], irradiance: 1.0}\n  - {type: point, position: [-1.5, 1, 0.5], intensity: 6}",
        "",
        lambda f: (
            {
                "sky": {"type": "constant", "radiance": 0.2},
                "sun": {"type": "directional", "direction": [0.5, -1.0, 0.2], "irradiance": 1.0},
                "bulb": {"type": "point", "position": [-1.5, 1, 0.5], "intensity": 6.0},
            },
            {},
        ),
    ),
    "keyed-point-sun-sky": (
        "  - {type: constant, radiance: 0.2}\n  - {type: directional, direction: [0.5, -1.0, 0.2], irradiance: 1.0}\n"
        "  - {type: point, position: [0, 3, 0], intensity: 10, " + _KEYED % ("translate", "[-1.5, 3, 0]", "[1.5, 3, 0]") + "}",
        "",
        lambda f: (
            {
                "sky": {"type": "constant", "radiance": 0.2},
                "sun": {"type": "directional", "direction": [0.5, -1.0, 0.2], "irradiance": 1.0},
                "bulb": {"type": "point", "position": [-1.5 + 3 * f, 3, 0], "intensity": 10.0},
            },
            {},
        ),
    ),
    "lamp-on-mover-sun-sky": (
        "  - {type: constant, radiance: 0.1}\n  - {type: directional, direction: [0.5, -1.0, 0.2], irradiance: 1.0}",
        _lamp_yaml(_KEYED % ("translate", "[-1.5, 2.0, 0]", "[0.5, 2.0, 0]")),
        lambda f: ({"sky": {"type": "constant", "radiance": 0.1}, "sun": {"type": "directional", "direction": [0.5, -1.0, 0.2], "irradiance": 1.0}}, _lamp_ref(-1.5 + 2 * f)),
    ),
    # a light type added as one record (scene/schema.py ProjectorLight): still, and keyed
    "projector": (
        f"  - {{type: projector, position: [1.5, 3, 1.5], look_at: [0, 0, 0], file: {SLIDE}, fov: 40, scale: 6}}",
        "",
        lambda f: ({"slide": _projector_ref([1.5, 3, 1.5], [0, 0, 0], 6.0)}, {}),
    ),
    "projector-keyed": (
        f"  - {{type: projector, position: [0, 3, 1.5], look_at: [0, 0, 0], file: {SLIDE}, fov: 40, scale: 6, "
        + _KEYED % ("translate", "[-1.5, 3, 1.5]", "[1.5, 3, 1.5]")
        + "}",
        "",
        # a keyed translate moves the frame: the aim (its rotation) stays the record's
        lambda f: ({"slide": {**_projector_ref([0, 3, 1.5], [0, 0, 0], 6.0), "to_world": _T().translate([-1.5 + 3 * f, 0, 0]) @ _spot_to_world([0, 3, 1.5], [0, 0, 0])}}, {}),
    ),
    "point-on-moving-parent": (
        "  - {type: point, parent: rig, position: [0, 3, 0], intensity: 10}",
        "  - {name: rig, shape: empty, " + _KEYED % ("translate", "[-1, 0, 0]", "[1, 0, 0]") + "}\n",
        lambda f: ({"bulb": {"type": "point", "position": [-1 + 2 * f, 3, 0], "intensity": 10.0}}, {}),
    ),
    # more moving lights than lights.EACH_MAX: candidates of the one light choice, posed at
    # each path's time, one shadow ray among them all
    "many-points-on-moving-parent": (
        "\n".join(f"  - {{type: point, parent: rig, position: {_MANY[k]}, intensity: 0.6}}" for k in range(len(_MANY))),
        "  - {name: rig, shape: empty, " + _KEYED % ("translate", "[-1, 0, 0]", "[1, 0, 0]") + "}\n",
        lambda f: ({f"bulb{k}": {"type": "point", "position": [p[0] - 1 + 2 * f, p[1], p[2]], "intensity": 0.6} for k, p in enumerate(_MANY)}, {}),
    ),
}


@pytest.mark.parametrize("case", list(LIGHT_CASES))
def test_every_light_agrees_with_mitsuba_path(tmp_path: Path, case: str) -> None:
    """Ours (cold frame 0, warm frame 2) against a hand-built Mitsuba `path` scene, judged
    against the noise floor of two reference seeds; and the picture is really lit."""
    activate()
    import mitsuba as mi

    from _render_support import render

    lights, extra, reference = LIGHT_CASES[case]
    text = _light_scene(lights, extra)
    if reference == "envmap":
        _env_image(tmp_path)
        env = {"type": "envmap", "filename": str(tmp_path / "sky.exr"), "scale": 1.5, "to_world": _T().rotate([0, 1, 0], 90)}
        reference = lambda f: ({"sky": env}, {})  # noqa: E731
    if reference == "envmap-smooth":
        from motion.pipeline.frame_output import write_frame

        smooth = np.linspace(0.5, 0.3, 16, dtype=np.float32)[:, None, None] * np.ones((16, 32, 3), np.float32)  # brighter overhead
        write_frame(tmp_path / "smooth.exr", smooth, pixel_type="float")
        env = {"type": "envmap", "filename": str(tmp_path / "smooth.exr")}
        sun = {"type": "directional", "direction": [0.5, -1.0, 0.2], "irradiance": 1.0}
        reference = lambda f: ({"sky": env, "sun": sun}, {})  # noqa: E731
    if case.startswith("projector"):
        _slide_image(tmp_path)
    loaded = load(tmp_path, text)
    images, stats, _ = render(loaded, [0, 2])
    assert [s.cold for s in stats] == [True, False]
    for frame, image in zip((0, 2), images):
        ours = image[..., :3]
        emitters, shapes = reference(frame / 2)
        emitters = _fill_slide(emitters, str(tmp_path / SLIDE))
        scene = _reference_scene(emitters, shapes)
        ref_a = np.array(mi.render(scene, seed=21, spp=LIGHT_SPP))[..., :3]
        ref_b = np.array(mi.render(scene, seed=22, spp=LIGHT_SPP))[..., :3]
        floor = np.abs(ref_a - ref_b).mean()
        err = np.abs(ours - ref_a).mean()
        assert np.isfinite(ours).all()
        assert err < 1.3 * floor, (case, frame, err, floor, ours.mean(), ref_a.mean())
        assert ours.mean() == pytest.approx(ref_a.mean(), rel=0.03), (case, frame)
        assert ref_a.std() > 0.02  # a lit picture, not two dark images agreeing


# --- lights within the shutter -----------------------------------------------------------

SHUTTER_SUBFRAMES = 32


@pytest.mark.parametrize("kind", ["point", "directional", "projector"])
def test_light_moving_within_the_shutter_is_placed_at_each_paths_time(tmp_path: Path, kind: str) -> None:
    """A light that moves a long way while the shutter is open: our stochastic frame equals
    the average of Mitsuba `path` renders at 32 instants across the shutter (light posed
    by the same linear keys, computed here), and clearly differs from the light frozen at
    the frame's time (what per-frame placement gave)."""
    activate()
    import mitsuba as mi

    from _render_support import render
    from motion.pipeline.bake import evaluate_frames

    if kind == "point":  # x from -3 to 3 over frames 0..2: 1.5 m during frame 1's shutter
        lights = "  - {type: point, position: [0, 2, 0], intensity: 10, " + _KEYED % ("translate", "[-3, 2, 0]", "[3, 2, 0]") + "}"

        def emitter(s: float) -> dict[str, Any]:
            return {"bulb": {"type": "point", "position": [-3 + 6 * s, 2, 0], "intensity": 10.0}}

    elif kind == "projector":  # the slide sweeps 1.5 m across the floor during frame 1's shutter
        _slide_image(tmp_path)
        lights = f"  - {{type: projector, position: [0, 3, 1.5], look_at: [0, 0, 0], file: {SLIDE}, fov: 40, scale: 6, " + _KEYED % ("translate", "[-3, 3, 1.5]", "[3, 3, 1.5]") + "}"

        def emitter(s: float) -> dict[str, Any]:
            ref = _projector_ref([0, 3, 1.5], [0, 0, 0], 6.0)
            return {"slide": _fill_slide({**ref, "to_world": _T().translate([-3 + 6 * s, 0, 0]) @ _spot_to_world([0, 3, 1.5], [0, 0, 0])}, str(tmp_path / SLIDE))}

    else:  # the sun swings 100 degrees while frame 1's shutter is open (frames 0.75 to 1.25)
        keyed = _KEYED.replace("time: 0,", "time: 0.75,").replace("time: 2,", "time: 1.25,")
        lights = "  - {type: directional, direction: [0, -1, 0], irradiance: 2.5, " + keyed % ("rotate", "[40, 0, 0]", "[140, 0, 0]") + "}"

        def emitter(s: float) -> dict[str, Any]:
            a = np.radians(40 + 100 * np.clip((s * 2 - 0.75) / 0.5, 0, 1))  # s * 2 = t in frames
            return {"sun": {"type": "directional", "direction": [0, -np.sin(a), np.cos(a)], "irradiance": 2.5}}

    spp = 256
    text = _light_scene(lights, blur="stochastic").replace(f"spp: {LIGHT_SPP}", f"spp: {spp}")
    loaded = load(tmp_path, text)
    (ours,), _, _ = render(loaded, [1])
    ours = ours[..., :3]
    (fi,) = evaluate_frames(loaded, [1])
    span = 2 / 24  # s = t / span: the point light's keys run from s = 0 to 1

    def shutter_average(seed: int) -> np.ndarray:
        acc = np.zeros_like(ours)
        for j in range(SHUTTER_SUBFRAMES):
            t = fi.shutter[0] + (j + 0.5) / SHUTTER_SUBFRAMES * (fi.shutter[1] - fi.shutter[0])
            scene = _reference_scene(emitter(t / span), spp=spp // SHUTTER_SUBFRAMES)
            acc += np.array(mi.render(scene, seed=seed * 1000 + j))[..., :3]
        return acc / SHUTTER_SUBFRAMES

    ref_a, ref_b = shutter_average(1), shutter_average(2)
    # Our paths draw their time at random (stratified); the reference's instants are fixed,
    # so it lacks the time variance. The floor of |ours - ref| is sqrt(s_ours^2 + s_ref^2),
    # each side's spread measured from two seeds of its own.
    (ours_b,), _, _ = render(load(tmp_path, text.replace("motion_blur: stochastic", "motion_blur: stochastic, seed: 77"), name="b.yaml"), [1])
    floor_ours = np.abs(ours - ours_b[..., :3]).mean()
    floor_ref = np.abs(ref_a - ref_b).mean()
    floor = np.sqrt((floor_ours**2 + floor_ref**2) / 2)
    err = np.abs(ours - ref_a).mean()
    assert err < 1.3 * floor, (err, floor_ours, floor_ref)
    assert ours.mean() == pytest.approx(ref_a.mean(), rel=0.01)
    frozen = np.array(mi.render(_reference_scene(emitter(fi.time / span), spp=spp), seed=3))[..., :3]
    assert np.abs(frozen - ref_a).mean() > 3 * floor  # the test can tell blur from a frozen light


def test_small_emissive_mover_converges_like_a_static_light(tmp_path: Path) -> None:
    """A small area light on a mover is reached by emitter sampling (in its rest frame) with
    MIS, not by BSDF sampling alone: at equal spp its error against a converged reference
    is that of the same light in the static set."""
    activate()
    import mitsuba as mi

    from _render_support import render

    lamp = (
        "  - {{name: lamp, shape: rectangle, width: 0.3, height: 0.3, emission: {{radiance: 80.0}}, material: black, "
        "transform: {{translate: [-0.5, 2.0, 0], rotate: {{euler: [90, 0, 0]}}}}{motion}}}\n"
    )
    still = ", " + _KEYED % ("translate", "[-0.5, 2.0, 0]", "[-0.5, 2.0, 0]")
    spp = 16
    errors = {}
    reference = None
    for label, motion in (("static", ""), ("mover", still)):
        text = _light_scene("  - {type: constant, radiance: 0.02}", lamp.format(motion=motion))
        text = text.replace(f"spp: {LIGHT_SPP}", f"spp: {spp}")
        loaded = load(tmp_path, text, name=f"{label}.yaml")
        (image,), _, renderer = render(loaded, [0])
        assert renderer.mover_names == ([] if label == "static" else ["lamp"])
        if reference is None:
            shapes = {"lamp": {**_LAMP, "emitter": {"type": "area", "radiance": 80.0}, "to_world": _T().translate([-0.5, 2.0, 0]) @ _T().rotate([1, 0, 0], 90) @ _T().scale([0.15, 0.15, 1])}}
            scene = _reference_scene({"sky": {"type": "constant", "radiance": 0.02}}, shapes, spp=2048)
            reference = np.array(mi.render(scene, seed=5))[..., :3]
        errors[label] = float(np.sqrt(np.mean((image[..., :3] - reference) ** 2)))
    assert errors["mover"] < 1.25 * errors["static"], errors


# --- light selection (render/kernel/lights.py) and exact sample counts (film.stratified_passes) ---


def test_sun_and_constant_sky_spend_no_light_sample_on_the_sky(tmp_path: Path) -> None:
    """Sun + constant sky: the sky is reached by BSDF sampling only and every light sample
    goes to the sun, so at equal spp our error against a converged `path` reference is well
    far below `path`'s own (which splits its light samples 50/50 and samples the sky over
    the whole sphere, as we did before render/kernel/lights.py)."""
    activate()
    import mitsuba as mi

    from _render_support import render

    lights = "  - {type: constant, radiance: 0.4}\n  - {type: directional, direction: [-0.4, -1.0, -0.3], irradiance: 2.5}"
    emitters = {"sky": {"type": "constant", "radiance": 0.4}, "sun": {"type": "directional", "direction": [-0.4, -1.0, -0.3], "irradiance": 2.5}}
    spp = 16
    text = _light_scene(lights).replace(f"spp: {LIGHT_SPP}", f"spp: {spp}")
    (ours,), _, _ = render(load(tmp_path, text), [0])
    reference = np.array(mi.render(_reference_scene(emitters, spp=1024), seed=9))[..., :3]
    theirs = np.array(mi.render(_reference_scene(emitters, spp=spp), seed=10))[..., :3]

    def rel_mse(image: np.ndarray) -> float:
        return float(np.mean((image - reference) ** 2 / (reference**2 + 1e-2)))

    # measured: 0.02x path's (0.22x before, from the stratified sampler alone)
    assert rel_mse(ours[..., :3]) < 0.08 * rel_mse(theirs), (rel_mse(ours[..., :3]), rel_mse(theirs))


def test_sample_count_asked_is_the_count_traced() -> None:
    """`spp: 32` traces 32 samples a pixel (two stratified passes of 16), not the 35 of
    Mitsuba's multijitter rounding; counts it takes as they are stay one pass."""
    activate()
    import drjit as dr
    import mitsuba as mi

    from motion.pipeline.render.kernel import film

    scene = mi.load_dict(
        {
            "type": "scene",
            "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 4}, "sampler": {"type": "multijitter", "sample_count": 4}},
            "ball": {"type": "sphere"},
        }
    )
    traced: list[int] = []

    def count(scene: Any, sampler: Any, ray: Any, medium: Any, active: Any) -> Any:
        traced.append(dr.width(ray.o))
        return mi.Spectrum(1.0), mi.Bool(True), []

    for spp, passes in ((32, 2), (36, 1), (96, 2), (37, 2)):
        traced.clear()
        film.render(count, scene, scene.sensors()[0], 3, spp)
        assert sum(traced) == 8 * 4 * spp and len(traced) == passes, (spp, traced)


def test_lights_chosen_by_contribution_beat_a_uniform_choice(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A point light near one end of the floor and a dim sun: choosing by estimated
    contribution (render/kernel/lights.py) gives a clearly lower error at equal spp than the same
    integrator choosing uniformly (DEFENSIVE = 1: every emitter equally likely, as `path`)."""
    activate()
    import mitsuba as mi

    from _render_support import render
    from motion.pipeline.render.kernel import lights as light_choice

    lights = "  - {type: directional, direction: [0.5, -1.0, 0.2], irradiance: 0.3}\n  - {type: point, position: [-1.5, 0.6, 0.5], intensity: 8}"
    emitters = {
        "sun": {"type": "directional", "direction": [0.5, -1.0, 0.2], "irradiance": 0.3},
        "bulb": {"type": "point", "position": [-1.5, 0.6, 0.5], "intensity": 8.0},
    }
    reference = np.array(mi.render(_reference_scene(emitters, spp=1024), seed=9))[..., :3]
    text = _light_scene(lights).replace(f"spp: {LIGHT_SPP}", "spp: 8")
    errors = {}
    for label, share in (("contribution", light_choice.DEFENSIVE), ("uniform", 1.0)):
        monkeypatch.setattr(light_choice, "DEFENSIVE", share)
        (image,), _, _ = render(load(tmp_path, text, name=f"{label}.yaml"), [0])
        errors[label] = float(np.mean((image[..., :3] - reference) ** 2 / (reference**2 + 1e-2)))
    assert errors["contribution"] < 0.5 * errors["uniform"], errors  # measured 0.2x
