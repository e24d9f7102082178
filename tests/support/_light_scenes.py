"""One light-agreement scene, two ways: our YAML and the same scene written by hand in
Mitsuba's own terms (rendered with `path`). Shared by tests/render/test_correctness.py and
bench/bench_lights.py. The reference never goes through our light builder: a light that we
place wrongly cannot agree with itself."""

from __future__ import annotations

from typing import Any

FLOOR_WIDTH = 8.0
# a red diffuse ball on the floor, for a shadow: (our YAML object, its reference shape)
BALL = "  - {name: ball, shape: sphere, radius: 0.4, material: ball, transform: {translate: [0.6, 0.4, 0.3]}}\n"


def light_scene_yaml(lights: str, objects: str = "", *, resolution: tuple[int, int], spp: int, blur: str = "off", last: int = 2) -> str:
    """A diffuse floor seen from (0, 5, 5), lit by `lights` (YAML list items), with the
    materials `floor`, `ball` and `black` available to `objects`."""
    return f"""
timeline: {{fps: 24, first: 0, last: {last}}}
camera: {{position: [0, 5, 5], look_at: [0, 0, 0], fov: 50}}
lights:
{lights}
materials:
  - {{name: floor, type: diffuse, color: 0.5}}
  - {{name: ball, type: diffuse, color: [0.7, 0.3, 0.2]}}
  - {{name: black, type: diffuse, color: 0.0}}
objects:
  - {{name: floor, shape: rectangle, width: {FLOOR_WIDTH}, height: {FLOOR_WIDTH}, material: floor, transform: {{rotate: {{euler: [-90, 0, 0]}}}}}}
{objects}
render: {{resolution: [{resolution[0]}, {resolution[1]}], spp: {spp}, max_depth: 3, rr_depth: 3, motion_blur: {blur}}}
"""


def ball_shape(mi: Any) -> dict[str, Any]:
    """The reference twin of BALL."""
    T = mi.ScalarTransform4f
    return {"ball": {"type": "sphere", "to_world": T().translate([0.6, 0.4, 0.3]) @ T().scale(0.4), "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}}}


def reference_scene(mi: Any, emitters: dict[str, Any], shapes: dict[str, Any] | None = None, *, resolution: tuple[int, int], spp: int) -> Any:
    """The floor and camera of `light_scene_yaml` in Mitsuba's own terms, lit by `emitters`,
    with Mitsuba's `path` integrator."""
    T = mi.ScalarTransform4f
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3, "rr_depth": 3},
        "sensor": {
            "type": "perspective",
            "fov": 50.0,
            "fov_axis": "x",
            "to_world": T().look_at(origin=[0, 5, 5], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": resolution[0], "height": resolution[1], "rfilter": {"type": "gaussian"}, "sample_border": False},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "floor": {
            "type": "rectangle",
            "to_world": T().rotate([1, 0, 0], -90) @ T().scale([FLOOR_WIDTH / 2, FLOOR_WIDTH / 2, 1]),
            "bsdf": {"type": "diffuse", "reflectance": 0.5},
        },
    }
    d.update(shapes or {})
    d.update(emitters)
    return mi.load_dict(d)
