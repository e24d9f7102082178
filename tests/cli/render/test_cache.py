"""The first-frame cache: warm frames reuse the scene, compile no kernels and touch no
shape of the static set; results are bit-identical whether a frame renders cold or warm,
in one process or another; seed policies are deterministic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion.pipeline.frame_output import read_frame
from _render_support import load
from _support import SCENES, run_motion

pytestmark = pytest.mark.render


_PROBE = """
import json, sys
from motion.pipeline import variant
variant.activate("auto", quiet=True)
from motion.pipeline.scene import load_scene
from motion.pipeline.bake import evaluate_frames
from motion.pipeline.render.worker.frame_renderer import FrameRenderer
import numpy as np
loaded = load_scene(sys.argv[1], {"render": {"resolution": [48, 32], "spp": 4, "max_depth": 3, "shutter_samples": 5}})
renderer = FrameRenderer(loaded)
out = []
for fi in evaluate_frames(loaded, [0, 1, 2, 3]):
    img, st = renderer.render(fi)
    out.append({"cold": st.cold, "compiled": st.kernels_compiled, "updated": list(st.updated_params),
                "reused": st.scene_reused, "mean": float(img[..., :3].mean()), "checksum": float((img * np.arange(img.size).reshape(img.shape) % 97).sum())})
print(json.dumps({"frames": out, "static": renderer.static_names, "variant": variant.activate().variant}))
"""


def test_warm_frames_compile_nothing_and_leave_the_static_set_alone(tmp_path: Path) -> None:
    """Run in a fresh process with an EMPTY kernel cache, so nothing is hidden by kernels
    that earlier runs left on disk."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, MOTION_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("DRJIT_CACHE_DIR", None)
    proc = subprocess.run([sys.executable, "-c", _PROBE, str(SCENES / "spinning-top.yaml")], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    frames = result["frames"]
    if result["variant"] == "scalar_rgb":
        pytest.skip("no kernels to compile in the scalar fallback")
    assert frames[0]["cold"] and frames[0]["compiled"] > 0  # the first frame pays
    assert not any(f["cold"] for f in frames[1:]) and all(f["reused"] for f in frames[1:])
    assert [f["compiled"] for f in frames[1:]] == [0, 0, 0], frames
    static = set(result["static"])
    assert "table" in static
    for f in frames[1:]:
        assert all(k.startswith("sensor.") for k in f["updated"]), f["updated"]  # no shape of the static set
    # and the top really moves between frames
    assert len({f["checksum"] for f in frames}) == 4


def test_cold_and_warm_frame_are_bit_identical_across_processes(tmp_path: Path) -> None:
    args = ["--preset", "ci-smoke", "--resolution", "48x32"]
    warm = run_motion("render", str(SCENES / "walk-cycle.yaml"), *args, "--frames", "0-3", "-o", str(tmp_path / "warm"))
    cold = run_motion("render", str(SCENES / "walk-cycle.yaml"), *args, "--frames", "3", "-o", str(tmp_path / "cold"))
    assert warm.returncode == 0 and cold.returncode == 0, warm.stderr + cold.stderr
    a = read_frame(tmp_path / "warm" / "walk-cycle.0003.exr")
    b = read_frame(tmp_path / "cold" / "walk-cycle.0003.exr")
    assert np.array_equal(a.rgba, b.rgba)
    assert a.meta["seed"] == b.meta["seed"] and a.meta["motion_hash"] == b.meta["motion_hash"]


def test_no_cache_path_gives_the_same_pixels(tmp_path: Path) -> None:
    args = ["--preset", "ci-smoke", "--resolution", "32x24", "--frames", "1-2"]
    a = run_motion("render", str(SCENES / "spinning-top.yaml"), *args, "-o", str(tmp_path / "cached"))
    b = run_motion("render", str(SCENES / "spinning-top.yaml"), *args, "--no-cache", "-o", str(tmp_path / "naive"))
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    for f in ("spinning-top.0001.exr", "spinning-top.0002.exr"):
        assert np.array_equal(read_frame(tmp_path / "cached" / f).rgba, read_frame(tmp_path / "naive" / f).rgba)


STILL = """
timeline: {fps: 24, first: 0, last: 3}
camera: {position: [0, 1, 3], look_at: [0, 0, 0]}
lights: [{type: constant, radiance: 0.3}, {type: point, position: [1, 2, 2], intensity: 5}]
materials: [{name: m, type: diffuse, color: 0.6}]
objects: [{name: s, shape: sphere, radius: 0.6, material: m}]
render: {resolution: [32, 24], spp: 2, max_depth: 3, seed: 7, seed_policy: %s}
"""


@pytest.mark.parametrize("policy", ["per-frame", "fixed"])
def test_seed_policy(tmp_path: Path, policy: str) -> None:
    """Through the worker's task path (render_frames), as the farm renders."""
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.identity import scene_hashes
    from motion.pipeline.render.worker.job import RenderJob, render_frames

    loaded = load(tmp_path, STILL % policy)
    job = RenderJob(str(loaded.path), {}, str(tmp_path / "out"), *scene_hashes(loaded))
    inputs = evaluate_frames(loaded, [0, 1])
    first = render_frames(job, inputs)
    again = render_frames(job, inputs[:1])  # frame 0 again, after frame 1
    a, b = (read_frame(r.path).rgba for r in first)
    a2 = read_frame(again[0].path).rgba
    assert np.array_equal(a, a2)  # the seed depends on the scene seed and frame number only
    assert first[0].ok and read_frame(first[0].path).meta["seed_policy"] == policy
    if policy == "fixed":
        assert np.array_equal(a, b)  # the same noise pattern every frame
    else:
        assert not np.array_equal(a, b)  # noise changes every frame (no screen door)


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_bits_do_not_depend_on_the_thread_count(tmp_path: Path) -> None:
    """1 vs 2 drjit threads (e.g. Dask workers on machines with different core counts):
    the same bits. 160x90 x 16 spp spans many of drjit's work blocks, and the gaussian
    filter splats every sample into 25 pixels, so an order-dependent film would differ.
    drjit threads are the LLVM backend's: the variant is chosen, on a GPU machine too."""
    common = ["--preset", "preview", "--resolution", "160x90", "--frames", "5", "--workers", "1", "--no-progress", "--variant", "llvm_ad_rgb"]
    for threads in ("1", "2"):
        proc = run_motion("render", str(SCENES / "spinning-top.yaml"), *common, "--threads", threads, "-o", str(tmp_path / threads))
        assert proc.returncode == 0, proc.stderr
    a = read_frame(tmp_path / "1" / "spinning-top.0005.exr").rgba
    b = read_frame(tmp_path / "2" / "spinning-top.0005.exr").rgba
    assert np.array_equal(a, b)
    # the same in passes (a 1080p frame at 256 spp runs as ~64 passes): 14,400 pixels x
    # 16 spp with at most 2^16 lanes a pass -> 4 passes of 4 spp, summed in pass order
    for threads in ("1", "2"):
        proc = run_motion("render", str(SCENES / "spinning-top.yaml"), *common, "--threads", threads, "-o", str(tmp_path / f"p{threads}"),
                          env={"MOTION_MAX_LANES": str(1 << 16)})
        assert proc.returncode == 0, proc.stderr
    c = read_frame(tmp_path / "p1" / "spinning-top.0005.exr").rgba
    d = read_frame(tmp_path / "p2" / "spinning-top.0005.exr").rgba
    assert np.array_equal(c, d)
    assert not np.array_equal(a, c)  # really another sampling (4 passes), yet the same picture:
    assert abs(float(a[..., :3].mean()) - float(c[..., :3].mean())) < 0.01 * float(a[..., :3].mean())


def test_a_worker_refuses_a_scene_edited_after_the_job_started(tmp_path) -> None:
    """Issue 26: a late or respawned worker loads the scene file again; if it was edited
    since the job was planned (its hashes differ), the worker renders nothing from it (its
    frames would carry the old hashes and --resume would trust them)."""
    import shutil

    from farm_util import SCENE
    from motion.pipeline.bake import bake
    from motion.pipeline.identity import scene_hashes
    from motion.pipeline.render.worker.job import RenderJob, render_frames
    from motion.pipeline.scene import load_scene

    scene = tmp_path / "farm-tiny.yaml"
    shutil.copy(SCENE, scene)
    loaded = load_scene(scene)
    scene_hash, settings_hash = scene_hashes(loaded)
    job = RenderJob(scene_path=str(scene), overrides={}, output_dir=str(tmp_path / "out"), scene_hash=scene_hash, settings_hash=settings_hash)
    frame = bake(loaded, [0]).frame(0)
    scene.write_text(scene.read_text().replace("radius: 0.3", "radius: 0.4"))  # edited after planning
    (result,) = render_frames(job, [frame])
    assert not result.ok and "changed after this render started" in (result.error or ""), result
    assert not (tmp_path / "out").exists()


def test_the_task_path_is_where_the_frame_is_written(tmp_path: Path) -> None:
    """Issue 26: the worker writes a frame where the task claimed and checked it
    (TaskContext.paths), not at a path it computes again: a task given another name
    inside the output folder gets its frame there, and nothing at the default name."""
    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.farm.claims import new_run_id
    from motion.pipeline.farm.task import TaskContext, run_chunk
    from motion.pipeline.identity import scene_hashes
    from motion.pipeline.render.worker.job import RenderJob, frame_path

    loaded = load(tmp_path, STILL % "fixed")
    out = tmp_path / "out"
    job = RenderJob(str(loaded.path), {}, str(out), *scene_hashes(loaded))
    inputs = evaluate_frames(loaded, [0])
    chosen = out / "shots" / "renamed.0000.exr"
    chosen.parent.mkdir(parents=True)
    result = run_chunk(0, job, inputs, TaskContext(new_run_id(), {0: str(chosen)}))
    assert [r.ok for r in result.results] == [True], result
    assert result.results[0].path == str(chosen)
    assert read_frame(chosen).meta["frame"] == 0
    assert not frame_path(job, loaded, 0).exists()


def test_the_settings_hash_follows_file_contents_not_where_they_lie(tmp_path: Path) -> None:
    """A frame's settings hash reads the files a scene names by their bytes: the same
    import scene hashes the same whatever the machine's cache folder (its converted meshes
    and skin arrays sit there: a Dask worker under another user refused the job as an edited
    scene), and a texture edited under the same name changes it (`--resume` replaced nothing
    and a warm worker kept serving the old texture)."""
    import os
    import subprocess
    import sys

    probe = ("import sys; from motion.pipeline.scene import load_scene; from motion.pipeline.identity import scene_hashes; "
             "print(scene_hashes(load_scene(sys.argv[1], assets=False))[1])")

    def settings_hash(scene: Path, cache: Path) -> str:
        env = {**os.environ, "MOTION_CACHE_DIR": str(cache)}
        return subprocess.run([sys.executable, "-c", probe, str(scene)], env=env, capture_output=True, text=True, check=True).stdout.strip()

    walker = SCENES / "walker.yaml"
    assert settings_hash(walker, tmp_path / "cache-a") == settings_hash(walker, tmp_path / "cache-b")
    shot = tmp_path / "shot"
    shot.mkdir()
    (shot / "tex.ppm").write_bytes(b"P6 1 1 255\n" + bytes([200, 10, 10]))
    (shot / "scene.yaml").write_text(
        "camera: {position: [0, 1, 4], look_at: [0, 0, 0]}\n"
        "materials: [{name: m, type: diffuse, color: {file: tex.ppm}}]\n"
        "objects: [{name: s, shape: sphere, material: m}]\n"
    )
    before = settings_hash(shot / "scene.yaml", tmp_path / "cache-a")
    (shot / "tex.ppm").write_bytes(b"P6 1 1 255\n" + bytes([10, 10, 200]))
    assert settings_hash(shot / "scene.yaml", tmp_path / "cache-a") != before
