"""Right on the GPU without one (issue 35): the scenes the motion_path kernel traces share one
SBT owner whose shape types cover theirs (on CUDA the other scenes' traces are disabled and
read as misses), and a frame in which drjit warns of a disabled trace fails, exit 3.

CI has no GPU: the CUDA construction (each traced scene built with the owner's root scene
among its properties) runs here on LLVM, and the warning goes through drjit's own log
path (its `jit_log`, the function drjit-core's OptiX code generator logs with)."""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from _support import SCENES

pytestmark = pytest.mark.render

EXAMPLES = sorted(p.name for p in SCENES.glob("*.yaml"))
DISABLED = (
    "jit_eval(): more than one OptiX shader binding table was used within a single kernel, which is not supported. "
    "Please split your kernel into smaller parts (e.g. using `dr::eval()`). Disabling this ray tracing operation to "
    "avoid potential undefined behavior."
)


def _ci_smoke(name: str) -> Any:
    from motion.pipeline.presets import load_preset, overrides_from
    from motion.pipeline.scene import load_scene

    preset, _ = load_preset("ci-smoke")
    return load_scene(SCENES / name, overrides_from(preset, {"render": {"resolution": (16, 9)}}))


def _built_scenes(monkeypatch: pytest.MonkeyPatch) -> dict[int, tuple[Any, dict[str, Any]]]:
    """Record every scene `mi.load_dict` builds from then on: id -> (scene, its dictionary)."""
    import mitsuba as mi

    built: dict[int, tuple[Any, dict[str, Any]]] = {}
    load = mi.load_dict

    def recording(d: dict[str, Any], *args: Any, **kwargs: Any) -> Any:
        out = load(d, *args, **kwargs)
        if isinstance(out, mi.Scene):
            built[id(out)] = (out, dict(d))
        return out

    monkeypatch.setattr(mi, "load_dict", recording)
    return built


def _optix_types(bits: int) -> int:
    """A scene's shape types as OptiX's pipeline key has them (a rectangle is a mesh)."""
    import mitsuba as mi

    rect, mesh = int(mi.ShapeType.Rectangle), int(mi.ShapeType.Mesh)
    return (bits & ~rect) | mesh if bits & rect == rect else bits


@pytest.mark.parametrize("name", EXAMPLES)
def test_every_scene_traced_in_one_kernel_shares_one_sbt_owner_covering_its_shape_types(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from _render_support import activate

    if activate() == "scalar_rgb":
        pytest.skip("the motion_path integrator needs an LLVM or CUDA variant")
    import gc

    import mitsuba as mi

    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.kernel import sbt
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.render.poses.stacked import stack_frame

    monkeypatch.setattr(sbt, "shares_sbt", lambda: True)  # the CUDA construction, on any variant
    loaded = _ci_smoke(name)
    (baked,) = evaluate_frames(loaded, [loaded.scene.timeline.first])
    gc.collect()
    built = _built_scenes(monkeypatch)
    cache = FrameRenderer(loaded).cache
    stacked = stack_frame(baked)
    cache.build(stacked)
    cache.set_frame(stacked, "stochastic")  # the broadphase is made with the frame's proxies
    world = cache.integrator.world
    traced = world.traced(cache.scene)
    owners = []
    for k, scene in enumerate(traced):
        assert id(scene) in built, f"{name}: traced scene {k} was not built from a dictionary"
        nested = [v for v in built[id(scene)][1].values() if isinstance(v, mi.Scene)]
        assert len(nested) == 1, f"{name}: traced scene {k} of {len(traced)} was built without an SBT owner: on CUDA its rays read as misses"
        owners.append(nested[0])
    assert all(o is owners[0] for o in owners), f"{name}: the traced scenes name {len({id(o) for o in owners})} SBT owners, not one"
    owner_types = _optix_types(int(owners[0].shape_types()))
    for k, scene in enumerate(traced):
        uncovered = _optix_types(int(scene.shape_types())) & ~owner_types
        assert not uncovered, f"{name}: traced scene {k} has shape types 0x{uncovered:x} its SBT owner lacks: on CUDA it does not build"
    assert len(owners[0].shapes()) == len(sbt.type_names(owner_types)), "one stand-in per shape type"


def test_the_owners_construction_leaves_cpu_frames_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    """The CUDA construction (every traced scene built against the owner's root) renders the
    same pixels on LLVM as the plain one: movers, slices (a skinned walker) and statics."""
    from _render_support import activate, render

    if activate() == "scalar_rgb":
        pytest.skip("the motion_path integrator needs an LLVM or CUDA variant")
    from motion.pipeline.render.kernel import sbt

    loaded = _ci_smoke("walker.yaml")
    plain, _, _ = render(loaded, [0])
    monkeypatch.setattr(sbt, "shares_sbt", lambda: True)
    shared, _, renderer = render(loaded, [0])
    assert renderer.cache.owner is not None and renderer.cache.owner.root is not None
    assert np.array_equal(plain[0], shared[0])


def test_scenes_traced_together_without_one_owner_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    from _render_support import activate

    activate()
    from motion.pipeline.render.kernel.sbt import SbtOwner, SbtOwnerError, check_shared
    from motion.pipeline.variant import load_dict

    ball = {"type": "scene", "ball": {"type": "sphere"}}
    floor = {"type": "scene", "floor": {"type": "rectangle"}}
    loose = [load_dict(floor), load_dict(ball)]
    check_shared(loose[:1], None)  # one scene: one SBT, whatever built it
    with pytest.raises(SbtOwnerError, match="2 scenes are traced in one kernel without a shared SBT owner"):
        check_shared(loose, None)
    owner = SbtOwner({"Mesh", "Sphere"}, share=True)
    ours = [owner.scene(floor), owner.scene(ball)]
    check_shared(ours, owner)
    with pytest.raises(SbtOwnerError, match="traced scene 1 of 2 was not built by the kernel's SBT owner"):
        check_shared([ours[0], loose[1]], owner)
    other = SbtOwner({"Mesh", "Sphere"}, share=True)
    with pytest.raises(SbtOwnerError, match="not built by the kernel's SBT owner"):
        check_shared([ours[0], other.scene(ball)], owner)
    meshes_only = SbtOwner({"Mesh"}, share=True)
    with pytest.raises(SbtOwnerError, match=r"shape types \['Sphere'\] that its SBT owner lacks"):
        meshes_only.scene(ball)


def test_a_render_whose_scenes_do_not_share_the_owner_stops_before_tracing() -> None:
    from _render_support import activate

    if activate() == "scalar_rgb":
        pytest.skip("the motion_path integrator needs an LLVM or CUDA variant")
    import mitsuba as mi

    from motion.pipeline.render.kernel.integrator import register
    from motion.pipeline.render.kernel.sbt import SbtOwner, SbtOwnerError
    from motion.pipeline.variant import load_dict

    register()
    from motion.pipeline.render.kernel.broadphase import Broadphase, sphere_proxies

    owner = SbtOwner({"Mesh", "Sphere", "Ellipsoids"})
    scene = owner.scene({"type": "scene", "integrator": {"type": "motion_path"}, "floor": {"type": "rectangle"},
                         "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().translate([0, 0, -4]), "film": {"type": "hdrfilm", "width": 4, "height": 4}}})
    integrator = scene.integrator()
    integrator.set_sbt_owner(owner)
    frame = (np.zeros((1, 2, 3)), np.tile([1.0, 0, 0, 0], (1, 2, 1)), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)), np.zeros(3))
    moving = {"template_offset": np.zeros((1, 3)), "template_box": np.array([[[-1.0] * 3, [1.0] * 3]]), "template_sphere": np.array([[0.0, 0.0, 0.0, 1.0]]), "reach": np.array([3.0])}
    broad = Broadphase(mi, owner.scene)
    broad.update(sphere_proxies(np.array([[0.0, 0.0, 0.0, 1.0]])))
    integrator.set_samples(2)
    integrator.set_moving(broad.scene, owner.scene({"type": "scene", "ball": {"type": "sphere"}}), 1, 0, {})
    integrator.set_frame(*frame, moving=moving)
    assert np.array(integrator.render(scene, spp=1)).shape == (4, 4, 4)
    integrator.set_moving(broad.scene, load_dict({"type": "scene", "ball": {"type": "sphere"}}), 1, 0, {})  # built without the owner
    integrator.set_frame(*frame, moving=moving)
    with pytest.raises(SbtOwnerError, match="traced scene 2 of 3 was not built by the kernel's SBT owner"):
        integrator.render(scene, spp=1)


def _jit_log() -> Any:
    """drjit-core's `jit_log(LogLevel, fmt, ...)`: the function its OptiX code generator
    warns with; its message goes to drjit's log callback like the real warning's."""
    import drjit as dr

    lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    log = getattr(lib, "_Z7jit_log8LogLevelPKcz")  # C++ linkage in drjit 1.5
    return lambda message: log(ctypes.c_int(dr.LogLevel.Warn.value), b"%s", message.encode())


def test_a_frame_with_a_disabled_trace_fails_and_the_job_exits_3(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from _render_support import activate

    if activate() == "scalar_rgb":
        pytest.skip("the warning comes from drjit's JIT (LLVM or CUDA variants)")
    from motion.cli.main import main
    from motion.pipeline.frame_output import read_frame
    from motion.pipeline.render.worker.scene_cache import SceneCache

    warn = _jit_log()
    set_frame = SceneCache.set_frame

    def frame_with_disabled_trace(self: SceneCache, fi: Any, *args: Any, **kwargs: Any) -> None:
        set_frame(self, fi, *args, **kwargs)
        if fi.frame == 1:  # what drjit logs while compiling such a frame's kernel on OptiX
            warn(DISABLED)

    monkeypatch.setattr(SceneCache, "set_frame", frame_with_disabled_trace)
    monkeypatch.setenv("MOTION_EXECUTOR", "inline")  # this process: the patched frame
    out = tmp_path / "out"
    code = main(["render", str(Path(__file__).parents[1] / "data" / "farm-tiny.yaml"), "-o", str(out), "--frames", "0-2", "--retries", "0", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 3, err
    failed = [line for line in err.splitlines() if line.startswith("error: frame 1:")]
    assert len(failed) == 1 and "drjit disabled ray tracing" in failed[0] and "shader binding table" in failed[0], err
    assert DISABLED in err  # drjit's own line still reaches the console
    assert sorted(p.name for p in out.glob("*.exr")) == ["farm-tiny.0000.exr", "farm-tiny.0002.exr"]
    assert read_frame(out / "farm-tiny.0002.exr").rgba.shape == (12, 16, 4)


def test_a_frame_without_engine_warnings_is_untouched() -> None:
    from _render_support import activate

    activate()
    import drjit as dr

    from motion.pipeline.render.worker.engine_log import EngineWarningError, watching

    warn = _jit_log()
    with watching() as quiet:
        warn("jit_run(): The generated kernel uses a more than 1 million variables (2000000) and will likely not run efficiently.")
    quiet.check()  # slow, not wrong: no failure
    with watching() as loud:
        with watching() as inner:  # nested blocks share one tee
            warn(DISABLED)
    with pytest.raises(EngineWarningError, match="drjit disabled ray tracing"):
        inner.check()
    with pytest.raises(EngineWarningError):
        loud.check()
    level = dr.log_level()
    dr.set_log_level(dr.LogLevel.Error)  # a quieter drjit is made to tell us
    try:
        with watching() as raised:
            warn(DISABLED)
        with pytest.raises(EngineWarningError):
            raised.check()
    finally:
        dr.set_log_level(level)
