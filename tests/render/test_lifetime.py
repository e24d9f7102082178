"""A finished job's renderer frees its scenes: nothing of it stays alive in the process, so
a worker that renders job after job (a Dask worker, the test suite) traces and renders
each as fast as its first."""

from __future__ import annotations

import gc
from pathlib import Path

import pytest

from _render_support import load, render

pytestmark = pytest.mark.render

SCENE = """
camera: {position: [0, 0.4, 4], look_at: [0, 0, 0], fov: 40}
timeline: {fps: 24, first: 0, last: 1}
render: {resolution: [16, 12], spp: 2, max_depth: 3}
lights: [{type: constant, radiance: 0.5}, {type: point, position: [1, 2, 2], intensity: 5}]
materials: [{name: white, type: diffuse, color: 0.8}, {name: metal, type: conductor}]
objects:
  - {name: ball, shape: sphere, radius: 0.5, material: white,
     motion: {type: keyframes, time_unit: seconds, channels: {translate: {keys: [{time: 0, value: [-1, 0, 0]}, {time: 0.1, value: [1, 0, 0]}]}}}}
  - {name: box, shape: cube, material: metal, size: [0.3, 0.3, 0.3]}
"""


def _live_jit_variables() -> int:
    import drjit as dr

    gc.collect()
    return len(dr.whos(True).splitlines())


def test_a_freed_renderer_leaves_no_jit_variable_alive(tmp_path: Path) -> None:
    """Three jobs one after the other leave the process as the first left it. The scene
    holds its integrator from C++ and the integrator held the job's other scenes and their
    SBT owner, which holds the scene: a cycle Python's collector cannot see, which kept
    some 420 JIT variables and every plugin of each job alive, and every later kernel
    traced the leaked plugins' calls."""
    loaded = load(tmp_path, SCENE)
    _, _, renderer = render(loaded, [0, 1])
    if not renderer.vectorized:
        pytest.skip("the scalar fallback keeps no JIT state")
    del renderer
    after_one = _live_jit_variables()
    for _ in range(3):
        render(loaded, [0, 1])
    assert _live_jit_variables() == after_one


def test_a_renderer_alive_at_exit_leaves_quietly(tmp_path: Path) -> None:
    """A process that exits holding a renderer prints nothing: its scene cache's
    finaliser, run by the interpreter's exit hook, made a drjit value while Mitsuba's
    module was half torn down ("module has no attribute 'Float'" tracebacks after a test
    session). The script plays the torn-down module: an exit hook of its own, which runs
    before the finalisers' (registered first), takes `mi` from the render modules."""
    import subprocess
    import sys

    (tmp_path / "scene.yaml").write_text(SCENE)
    code = ("import sys; sys.path.insert(0, 'tests/support')\n"
            "from pathlib import Path\n"
            "from _render_support import load, render\n"
            f"KEPT = render(load(Path({str(tmp_path)!r}), Path({str(tmp_path / 'scene.yaml')!r}).read_text(), 'again.yaml'), [0])\n"
            "import atexit, motion.pipeline.render.kernel.integrator as I, motion.pipeline.render.poses.kernel as P\n"
            "atexit.register(lambda: (setattr(I, 'mi', None), setattr(P, 'mi', None)))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=Path(__file__).resolve().parents[2])
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
