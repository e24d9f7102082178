"""One traversal for everything that moves (render/kernel/world.py): the kernel's ray-tracing
calls do not depend on how many rigid movers or particles a scene has, nor on how many
samples across the shutter were baked; particles are spheres on their baked path, so a
fast particle leaves the streak a rigid sphere with the same motion leaves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _render_support import load, render

pytestmark = pytest.mark.render


def _movers_scene(count: int, samples: int) -> str:
    side = int(np.ceil(np.sqrt(count)))
    lines = [
        "name: traces",
        "timeline: {fps: 24, first: 0, last: 0}",
        "camera: {position: [0, 9, 7], look_at: [0, 0, 0], fov: 50, shutter: {angle: 180}}",
        "lights: [{type: constant, radiance: 1.0}, {type: point, position: [0, 5, 0], intensity: 10}]",
        "objects:",
        "  - {name: ground, shape: rectangle, width: 12, height: 12, transform: {rotate: {euler: [-90, 0, 0]}}}",
    ]
    for k in range(count):
        x, z = (k % side - side / 2) * 0.3, (k // side - side / 2) * 0.3
        lines.append(f"  - {{name: p{k}, shape: empty, transform: {{translate: [{x:.3f}, 0.2, {z:.3f}]}}, motion: {{type: procedural, generators: [{{type: turntable, rate: 720}}]}}}}")
        lines.append(f"  - {{name: b{k}, shape: sphere, radius: 0.08, parent: p{k}, transform: {{translate: [0.05, 0, 0]}}}}")
    lines.append(f"render: {{resolution: [8, 6], spp: 1, max_depth: 3, shutter_samples: {samples}}}")
    return "\n".join(lines) + "\n"


def _traces(tmp_path: Path, text: str) -> list[str]:
    from motion.pipeline.render.kernel import world

    loaded = load(tmp_path, text)
    before = len(world.TRACES)
    render(loaded, [0])
    return world.TRACES[before:]


def _counts(tmp_path: Path, cases: list[tuple[int, int]]) -> dict[tuple[int, int], list[str]]:
    out = {}
    for n, samples in cases:
        folder = tmp_path / f"{n}-{samples}"
        folder.mkdir()
        out[(n, samples)] = _traces(folder, _movers_scene(n, samples))
    return out


# the static scene, the broadphase and the atlas for the nearest hit; for the one shadow
# ray (the point light), the static scene, the broadphase walk and the atlas
SITES = ["intersect", "intersect", "intersect", "occluded", "intersect", "occluded"]


def test_the_kernels_trace_sites_do_not_grow_with_movers_or_time_samples(tmp_path: Path) -> None:
    """Before one traversal, each mover added its own trace sites (two per mover and light
    strategy), so 1,000 movers compiled a kernel 600x as slow as one."""
    counts = _counts(tmp_path, [(1, 9), (10, 2), (10, 4), (10, 64)])
    assert all(c == SITES for c in counts.values()), {k: len(v) for k, v in counts.items()}


def test_the_trace_sites_do_not_grow_with_emissive_movers(tmp_path: Path) -> None:
    """The emitters on things that move are one sampler over the atlas (lights.py
    `MovingEmitters`): with 1, 10 and 40 glowing movers the kernel has one more shadow ray
    than without, whatever their number. Before, each emissive mover was a strategy of its
    own with its own `occluded` (and a rest-frame scene of its own to sample)."""
    counts = {}
    for n in (1, 10, 40):
        folder = tmp_path / str(n)
        folder.mkdir()
        counts[n] = _traces(folder, _movers_scene(n, 9).replace("radius: 0.08,", "radius: 0.08, emission: {radiance: 2.0},"))
    assert all(c == [*SITES, "occluded", "intersect", "occluded"] for c in counts.values()), {k: len(v) for k, v in counts.items()}


def test_the_trace_sites_do_not_grow_with_many_moving_lights(tmp_path: Path) -> None:
    """Up to `lights.EACH_MAX` moving lights are each sampled at every vertex (their own
    shadow ray: exact but for visibility, the better time to equal error for a few lamps);
    past that they are candidates of the one light choice with the static scene's emitters,
    one shadow ray for all, so a shot of many moving lights keeps the kernel's size: the
    same sites for EACH_MAX + 1 and 40 of them, as for one static light."""
    from motion.pipeline.render.kernel.lights import EACH_MAX

    def lights(n: int) -> str:
        return ", ".join(
            f"{{type: point, position: [{k * 0.1 - 2:.1f}, 4, 0], intensity: 1, motion: {{type: procedural, generators: [{{type: ballistic, v0: [1, 0, 0], a: [0, 0, 0]}}]}}}}"
            for k in range(n))

    counts = {}
    for n in (1, EACH_MAX + 1, 40):
        folder = tmp_path / str(n)
        folder.mkdir()
        counts[n] = _traces(folder, _movers_scene(4, 9).replace("{type: point, position: [0, 5, 0], intensity: 10}]", f"{lights(n)}]"))
    assert counts[EACH_MAX + 1] == counts[40] == SITES, {k: len(v) for k, v in counts.items()}
    # one moving light: its own shadow ray (the static scene, the walk, the atlas), and no choice
    assert counts[1] == ["intersect", "intersect", "intersect", "occluded", "intersect", "occluded"]


@pytest.mark.slow
def test_the_trace_sites_are_the_same_for_a_thousand_movers(tmp_path: Path) -> None:
    counts = _counts(tmp_path, [(100, 9), (1000, 9)])
    assert all(c == SITES for c in counts.values()), {k: len(v) for k, v in counts.items()}


PARTICLE = """
name: streak
timeline: {fps: 24, first: 0, last: 1}
camera: {type: orthographic, position: [0, 0, -10], look_at: [0, 0, 0], ortho_width: 4, shutter: {angle: 180}}
lights: [{type: constant, radiance: 1.0}]
materials: [{name: white, type: diffuse, color: [0.9, 0.9, 0.9]}, {name: dark, type: diffuse, color: [0.05, 0.05, 0.05]}]
dynamics: {gravity: [0, 0, 0]}
render: {resolution: [96, 24], spp: 256, max_depth: 2}
objects:
  - {name: back, shape: rectangle, width: 20, height: 20, material: white, transform: {translate: [0, 0, 5], rotate: {euler: [0, 180, 0]}}}
"""


def test_a_fast_particle_streaks_like_a_rigid_sphere_with_the_same_motion(tmp_path: Path) -> None:
    """A particle and a rigid sphere of the same radius, moving the same way (60 m/s across
    the frame, a 180-degree shutter, frame 1 at 1/24 s: the streak from x = -0.625 to
    0.625): the same continuous streak within noise, no gaps, at default settings (the
    time slices particles were once drawn as left `time_slices` separate dots)."""
    rigid = PARTICLE + """  - {name: ball, shape: sphere, radius: 0.1, material: dark, motion: {type: procedural, generators: [{type: ballistic, x0: [-2.5, 0, 0], v0: [60, 0, 0], a: [0, 0, 0]}]}}
"""
    particle = PARTICLE + """  - {name: spray, shape: particles, radius: 0.1, material: dark, emitter: {rate: 1, start: 0, stop: 0.001, lifetime: 10, position: [-2.5, 0, 0], direction: [1, 0, 0], speed: 60, spread: 0}}
"""
    (a,), _, _ = render(load(tmp_path, rigid, "rigid.yaml"), [1])
    (b,), _, _ = render(load(tmp_path, particle, "particle.yaml"), [1])
    row_a = a[11:13, :, 0].mean(axis=0)  # the streak's middle rows
    row_b = b[11:13, :, 0].mean(axis=0)
    x = 2.0 - (np.arange(96) + 0.5) * 4.0 / 96  # world x of each column (camera +X is image left)
    inside = np.abs(x) < 0.5  # well inside the streak: the ball covers each point a share of the shutter
    assert inside.sum() > 20
    background = row_a[np.abs(x) > 1.0].mean()
    assert (row_a[inside] < 0.95 * background).all(), "the rigid sphere leaves a continuous streak"
    # the particle the same, column by column within noise: no gaps (a gap is as bright as the back)
    np.testing.assert_allclose(row_b[inside], row_a[inside], atol=0.05)


# Each frame rendered by a fresh renderer, three times over, with one drjit thread (a farm
# worker on a 2-core machine with --workers 2): every render of a frame is the same bits.
# The atlas's moved meshes were once read by Mitsuba's scene build before their updates had
# run on drjit's queue, and a mover's triangles went missing in about one render in three.
_ONE_THREAD = """
import gc, json, sys
from pathlib import Path
import numpy as np, yaml
sys.path.insert(0, sys.argv[1])
import _render_support as rs
rs.activate()
import drjit as dr
dr.set_thread_count(1)
from motion.pipeline.bake import evaluate_frames
from motion.pipeline.render.worker.frame_renderer import FrameRenderer
from motion.pipeline.scene import load_scene
loaded = load_scene(Path(sys.argv[2]))
frames = evaluate_frames(loaded, list(range(8)))
first, worst = {}, 0.0
for _ in range(3):
    for fi in frames:
        gc.collect()
        image = FrameRenderer(loaded).render(fi)[0]
        first.setdefault(fi.frame, image)
        worst = max(worst, float(np.abs(image - first[fi.frame]).max()))
print(json.dumps({"worst": worst}))
"""


@pytest.mark.slow  # 24 fresh renderers in a process of its own (15-35 s): CI's second step
def test_every_render_of_a_frame_is_the_same_with_one_drjit_thread(tmp_path: Path) -> None:
    """A keyed box crossing the frame, 8 frames each rendered by a fresh renderer three
    times in one process with one drjit thread: the same pixels every time."""
    import json
    import subprocess
    import sys

    import yaml
    from tests.cli.shot.test_reruns import SHOT

    scene = tmp_path / "keys.yaml"
    scene.write_text(yaml.safe_dump(SHOT, sort_keys=False))
    script = tmp_path / "one_thread.py"
    script.write_text(_ONE_THREAD)
    run = subprocess.run([sys.executable, str(script), str(Path(__file__).parents[1] / "support"), str(scene)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert json.loads(run.stdout.strip().splitlines()[-1])["worst"] == 0.0


_SHARED = """\
name: shared
timeline: {fps: 24, first: 0, last: 24}
camera: {position: [0, 6, 5], look_at: [0, 0, 0], fov: 45, shutter: {angle: 180}}
lights: [{type: constant, radiance: 1.0}, {type: point, position: [0, 4, 1], intensity: 8}]
materials: [{name: red, type: diffuse, color: [0.8, 0.2, 0.1]}, {name: grey, type: diffuse, color: 0.5}]
objects:
  - {name: ground, shape: rectangle, width: 8, height: 8, material: grey, transform: {rotate: {euler: [-90, 0, 0]}}}
  - {name: p0, shape: empty, transform: {translate: [-1.5, 0.4, 0]}, motion: {type: procedural, generators: [{type: turntable, rate: 720}]}}
  - {name: b0, shape: sphere, radius: 0.3, material: red, parent: p0, transform: {translate: [0.3, 0, 0]}}
  - {name: p1, shape: empty, transform: {translate: [0, 0.4, 0]}, motion: {type: procedural, generators: [{type: turntable, rate: 360}]}}
  - {name: b1, shape: sphere, radius: 0.3, material: red, parent: p1, transform: {translate: [0.3, 0, 0]}}
  - {name: b2, shape: sphere, radius: 0.3, material: red, transform: {translate: [1.5, 0.4, 0]},
     motion: {type: keyframes, channels: {scale: {keys: [{time: 0, value: 1.0}, {time: 24, value: 1.6}]}}}}
  - {name: b3, shape: sphere, radius: 0.3, material: grey, transform: {translate: [0, 0.4, 1.5]},
     motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: [0, 0.4, 1.5]}, {time: 24, value: [1, 0.4, 1.5]}]}}}}
render: {resolution: [48, 36], spp: 16, max_depth: 3}
"""


def test_movers_of_the_same_shapes_share_one_atlas_cell_and_each_renders_as_its_own(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Movers whose rest-frame shapes are the same (a ball of one radius and material,
    however each moves) share one cell of the atlas and one copy of the shapes
    (render/kernel/atlas.py: 0.15 s of a 1,000-ball first frame was building 1,000 copies): each
    still renders at its own pose, as with a cell each. A mover whose scale changes leaves
    its shared cell for one of its own (the atlas is built again), and one of another
    material never shares."""
    from motion.pipeline.render.kernel import atlas as atlas_mod

    loaded = load(tmp_path, _SHARED)
    shared, stats, renderer = render(loaded, [0, 12, 24])
    atlas = renderer.cache.atlas
    names = renderer.cache.roles.mover_names
    assert sorted(names) == ["b0", "b1", "b2", "b3"]
    cells = dict(zip(names, atlas.cell_of))
    assert cells["b3"] != cells["b0"] and cells["b0"] == cells["b1"]  # another material: a cell of its own
    assert cells["b2"] != cells["b0"]  # at frame 24 its scale is 1.6: out of the shared cell
    assert len(atlas.scene.shapes()) == 3  # the balls of b0 and b1 built once
    assert any(k.startswith("mover:b2") for k in stats[1].updated_params)
    monkeypatch.setattr(atlas_mod, "_sharing_key", lambda dicts: None)  # every template a cell of its own
    alone, _, renderer = render(loaded, [0, 12, 24])
    assert len(renderer.cache.atlas.scene.shapes()) == 4
    for a, b in zip(shared, alone):  # the same picture: only the cells' offsets differ (float rounding)
        assert float(np.abs(a - b).max()) < 1e-3, float(np.abs(a - b).max())
        assert float(a[..., :3].mean()) > 0.05


# A deforming mesh (a cube skinned to one bone) against its rigid twin with the same motion:
# moved by its object (the bone still), or by its bone (the object still).
_SKIN = "deform: {type: skinning, auto: true, detail: 2, bones: [{name: root, length: 0.1%s}]}"


def _twins(tmp_path: Path, motion: str, size: float = 0.2, by_bone: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Frame 1 of a dark cube with `motion`, rigid and deforming, over the white back."""
    cube = f"shape: cube, size: [{size}, {size}, {size}], material: dark"
    rigid = PARTICLE + f"  - {{name: box, {cube}, motion: {motion}}}\n"
    skin = _SKIN % (f", motion: {motion}" if by_bone else "")
    deforming = PARTICLE + f"  - {{name: box, {cube}, {'' if by_bone else f'motion: {motion}, '}{skin}}}\n"
    (a,), _, _ = render(load(tmp_path, rigid, "rigid.yaml"), [1])
    (b,), _, renderer = render(load(tmp_path, deforming, "deforming.yaml"), [1])
    assert renderer.deforming_names == ("box",) and not renderer.mover_names  # in the one traversal
    return a, b


FLY = "{type: procedural, generators: [{type: ballistic, x0: [-2.5, 0, 0], v0: [60, 0, 0], a: [0, 0, 0]}]}"


@pytest.mark.parametrize("by_bone", [False, True], ids=["object", "bone"])
def test_a_deforming_mesh_moved_by_translation_streaks_like_its_rigid_twin(tmp_path: Path, by_bone: bool) -> None:
    """A skinned cube and the same rigid cube, both flying at 60 m/s across the frame (a
    180-degree shutter, frame 1: the streak from x = -0.625 to 0.625), moved by its object
    or by its bone: the same continuous streak within noise, column by column, with no
    gaps. Before, the deforming cube was `time_slices` (4) frozen copies: 4 dark squares
    with the back showing between them."""
    a, b = _twins(tmp_path, FLY, by_bone=by_bone)
    row_a = a[11:13, :, 0].mean(axis=0)
    row_b = b[11:13, :, 0].mean(axis=0)
    x = 2.0 - (np.arange(96) + 0.5) * 4.0 / 96
    inside = np.abs(x) < 0.6
    background = row_a[np.abs(x) > 1.0].mean()
    assert (row_a[inside] < 0.95 * background).all(), "the rigid cube leaves a continuous streak"
    assert (row_b[inside] < 0.95 * background).all(), "no gaps along the deforming cube's streak"
    np.testing.assert_allclose(row_b[inside], row_a[inside], atol=0.05)
    # the whole picture, in 4 x 4 blocks: the same within noise (256 spp of a [0, 1] estimate)
    blocks_a = a[..., 0].reshape(6, 4, 24, 4).mean(axis=(1, 3))
    blocks_b = b[..., 0].reshape(6, 4, 24, 4).mean(axis=(1, 3))
    np.testing.assert_allclose(blocks_b, blocks_a, atol=0.03)


def test_a_spinning_deforming_mesh_blurs_like_its_rigid_twin(tmp_path: Path) -> None:
    """A skinned cube and the same rigid cube, spinning about the view axis at 2,160
    degrees/s (45 degrees within the shutter): the same blurred square, block by block,
    within noise: the fitted track's rotation is slerped at each lane's time, as the rigid
    cube's is."""
    a, b = _twins(tmp_path, "{type: procedural, generators: [{type: turntable, axis: [0, 0, 1], rate: 2160}]}", size=0.6)
    blocks_a = a[..., 0].reshape(6, 4, 24, 4).mean(axis=(1, 3))
    blocks_b = b[..., 0].reshape(6, 4, 24, 4).mean(axis=(1, 3))
    background = a[..., 0].mean()
    assert blocks_a.min() < 0.5 * background  # the square's middle, always covered
    partial = (blocks_a > 0.2 * background) & (blocks_a < 0.8 * background)
    assert partial.sum() >= 4, "the corners blur"
    np.testing.assert_allclose(blocks_b, blocks_a, atol=0.03)


def test_the_trace_sites_do_not_grow_with_deforming_meshes(tmp_path: Path) -> None:
    """Deforming meshes are movers of the same broadphase and atlas: the same trace sites
    with 0, 1 and 6 of them, beside rigid movers or alone, for 4 and 9 baked samples.
    Before, each deforming mesh added a trace site per time slice to `intersect` and to
    every `occluded`."""
    def scene(movers: int, samples: int, deforming: int) -> str:
        text = _movers_scene(movers, samples).replace("render:", "%s\nrender:")
        lines = [
            f"  - {{name: d{k}, shape: capsule, radius: 0.1, height: 0.3, transform: {{translate: [{k * 0.25 - 1:.2f}, 0.5, 1]}}, "
            f"motion: {{type: procedural, generators: [{{type: ballistic, v0: [2, 0, 0], a: [0, 0, 0]}}]}}, {_SKIN % ''}}}"
            for k in range(deforming)
        ]
        return text.replace("%s\n", "".join(line + "\n" for line in lines))

    cases = [(4, 9, 0), (4, 9, 1), (4, 4, 6), (0, 9, 1), (0, 4, 6)]
    counts = {}
    for case in cases:
        folder = tmp_path / "-".join(map(str, case))
        folder.mkdir()
        counts[case] = _traces(folder, scene(*case))
    assert all(c == SITES for c in counts.values()), {k: len(v) for k, v in counts.items()}
