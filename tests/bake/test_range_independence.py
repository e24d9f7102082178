"""A frame's baked motion, hash and pixels do not depend on which other frames were
selected (issue 16): a farm manager hands out ranges such as 0-23, 0-25 and 20-40, and
their common frames must be the same frames, bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from farm_util import TINY, frames_in, motion, report
from motion.pipeline.bake import BakedFrame, bake, simulation_range
from motion.pipeline.identity import leaves
from motion.pipeline.farm.frame_inputs import baked_inputs, simulation_for
from motion.pipeline.frame_output import read_frame
from motion.pipeline.scene import load_scene

RANGES = [(0, 23), (0, 25), (20, 40)]


def _scene(tmp_path: Path, integrator: str = "rk4", particles: bool = False) -> Path:
    """A ball thrown over a floor it bounces on (step 7 ms: not a divisor of a frame),
    optionally with a seeded particle fountain; 48 frames at 24 fps."""
    objects = [
        {"name": "floor", "shape": "rectangle", "width": 8, "height": 8, "material": "grey",
         "collider": {"restitution": 0.6, "friction": 0.3}, "transform": {"rotate": {"euler": [-90, 0, 0]}}},
        {"name": "ball", "shape": "sphere", "radius": 0.25, "material": "red", "transform": {"translate": [-1.5, 1.2, 0]},
         "motion": {"type": "dynamics", "mass": 1.0, "velocity": [1.3, 2.0, 0.2], "restitution": 0.6}},
    ]
    if particles:
        objects.append({"name": "spray", "shape": "particles", "radius": 0.02, "material": "red",
                        "emitter": {"rate": 200, "lifetime": 0.8, "speed": 3.0, "spread": 20, "seed": 3, "direction": [0, 1, 0]}})
    doc = {
        "name": f"range-{integrator}",
        "timeline": {"fps": 24, "first": 0, "last": 47},
        "camera": {"position": [0, 1.5, 5], "look_at": [0, 0.5, 0], "fov": 50, "shutter": {"angle": 180}},
        "lights": [{"type": "constant", "radiance": 0.6}],
        "materials": [{"name": "grey", "type": "diffuse", "color": 0.5}, {"name": "red", "type": "diffuse", "color": [0.8, 0.2, 0.1]}],
        "dynamics": {"integrator": integrator, "step": 0.007},
        "objects": objects,
        "render": {"resolution": [16, 12], "spp": 1, "max_depth": 2, "shutter_samples": 3},
    }
    path = tmp_path / f"range-{integrator}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _flatten(fi: BakedFrame) -> dict[str, np.ndarray]:
    """Every number of a BakedFrame by a readable key (the fingerprint's own walk)."""
    return dict(leaves(fi))


@pytest.mark.parametrize("integrator,particles", [("rk4", False), ("rk45", False), ("semi-implicit-euler", True)])
def test_baked_motion_does_not_depend_on_the_selection(tmp_path: Path, integrator: str, particles: bool) -> None:
    loaded = load_scene(_scene(tmp_path, integrator, particles))
    runs = {}
    for lo, hi in RANGES:
        frames = list(range(lo, hi + 1))
        runs[(lo, hi)] = {fi.frame: _flatten(fi) for fi in baked_inputs(loaded, frames, simulation_for(loaded, frames))}
        # bake() without a given simulation takes the same range
        assert simulation_range(loaded, frames) == simulation_range(loaded, [0])
    checked = 0
    for a in RANGES:
        for b in RANGES:
            for f in set(runs[a]) & set(runs[b]):
                fa, fb = runs[a][f], runs[b][f]
                assert fa.keys() == fb.keys()
                for key in fa:
                    assert np.array_equal(fa[key], fb[key]), f"frame {f} {key}: {a} and {b} differ by {np.abs(fa[key] - fb[key]).max()}"
                checked += 1
    assert checked > 0
    plain = bake(loaded, [23])
    assert np.array_equal(plain.frame(23).across_shutter.objects["ball"].translation, runs[(0, 25)][23]["/across_shutter/objects/ball/translation"])


def test_frames_of_overlapping_ranges_are_the_same_frames(tmp_path: Path) -> None:
    """Render 0-23, then 0-25 into the same folder (0-23 are kept: same hash), then
    20-40 into a fresh folder: the common frames are identical pixels."""
    scene = _scene(tmp_path)
    a, b = tmp_path / "a", tmp_path / "b"
    r = motion("render", scene, "-o", a, "--frames", "0-23", *TINY, "--workers", "1")
    assert r.returncode == 0, r.stderr
    first = {p.name: read_frame(p).rgba for p in frames_in(a)}
    r = motion("render", scene, "-o", a, "--frames", "0-25", *TINY, "--workers", "1")
    assert r.returncode == 0, r.stderr
    rep = report(a)
    assert rep["totals"]["skipped"] == 24 and rep["totals"]["rendered"] == 2, rep["totals"]
    assert motion("render", scene, "-o", a, "--frames", "0-25", "--check").returncode == 0
    r = motion("render", scene, "-o", b, "--frames", "20-40", *TINY, "--workers", "1")
    assert r.returncode == 0, r.stderr
    second = {p.name: read_frame(p).rgba for p in frames_in(b)}
    common = sorted(set(second) & {p.name for p in frames_in(a)})
    assert len(common) == 6
    for name in common:
        assert np.array_equal(read_frame(a / name).rgba, second[name]), name
        if name in first:
            assert np.array_equal(first[name], second[name]), name


def _renumbered(tmp_path: Path, first: int) -> Path:
    """The ball-and-fountain scene, its 48 frames numbered from `first`, with a second ball
    released at `start: 0.5` (seconds on the dynamics clock)."""
    folder = tmp_path / f"f{first}"
    folder.mkdir()
    doc = yaml.safe_load(_scene(folder, "rk4", particles=True).read_text())
    doc["name"] = "renumbered"
    doc["timeline"] = {"fps": "24000/1001", "first": first, "last": first + 47}
    doc["objects"].append({"name": "late", "shape": "sphere", "radius": 0.2, "material": "red", "transform": {"translate": [1.0, 1.5, 0]},
                           "motion": {"type": "dynamics", "mass": 1.0, "start": 0.5}})
    path = folder / "renumbered.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_the_simulation_starts_with_the_shot(tmp_path: Path) -> None:
    """Issue 23: a shot numbered from 1001 simulates what the same shot numbered from 0
    does: the clock starts at the first frame (not 41.7 s earlier, when the ball would have
    left the floor long before frame 1001), and `start:` counts from there."""
    zero, late = load_scene(_renumbered(tmp_path, 0)), load_scene(_renumbered(tmp_path, 1001))
    t0, _ = simulation_range(late)
    assert 41.70 < t0 < 41.75  # frame 1001 at 24000/1001 fps opens its shutter at 41.7 s
    frames = [0, 11, 12, 13, 30, 47]
    a = {fi.frame: fi for fi in baked_inputs(zero, frames, simulation_for(zero, frames))}
    b = {fi.frame: fi for fi in baked_inputs(late, [1001 + f for f in frames], simulation_for(late, [1001 + f for f in frames]))}
    for f in frames:
        for name in ("ball", "late"):
            pa = a[f].across_shutter.objects[name].translation
            pb = b[1001 + f].across_shutter.objects[name].translation
            assert np.allclose(pa, pb, atol=1e-6), (f, name, pa, pb)
        assert np.array_equal(a[f].across_shutter.particles["spray"].alive, b[1001 + f].across_shutter.particles["spray"].alive), f
    # the late ball is held until 0.5 s after the first frame (frame 12 at 23.976 fps), then falls
    held = b[1001 + 11].at_frame.objects["late"].translation[0]
    assert np.allclose(held, [1.0, 1.5, 0.0]), held
    assert b[1001 + 30].at_frame.objects["late"].translation[0][1] < 1.4
    assert b[1001].at_frame.objects["ball"].translation[0][1] > 1.0  # in the air at the start, not 1,470 m below the floor
