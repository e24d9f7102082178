"""drjit's kernel cache as a CI job sees it (issue 38.6): `motion cache warm` compiles every
kernel the job renders with, and what else lives in a worker process never makes a new one.

A render kernel's IR holds the registry ids of every live Mitsuba BSDF, shape and emitter
of the process (the domains of its virtual calls), so one stray instance, or one freed by
the garbage collector half way through a build, makes a kernel no warm-up compiled."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from farm_util import MOTION, SCENE, _auto, report

pytestmark = pytest.mark.render

# A worker's cold frame in a fresh process; with `junk`, a Mitsuba BSDF left in a reference
# cycle that the collector has not reached yet (it runs when allocation counts say so)
_COLD_FRAME = r"""
import gc, json, sys
from motion.pipeline.bake import bake
from motion.pipeline.scene.loader import load_scene
from motion.pipeline.variant import activate

loaded = load_scene(sys.argv[1], {"render": {"resolution": [16, 12], "spp": 1}})
activate("auto")
import mitsuba as mi
from motion.pipeline.render.worker.frame_renderer import FrameRenderer

gc.disable()
if sys.argv[2] == "junk":
    junk = [mi.load_dict({"type": "conductor"})]
    junk.append(junk)
    del junk
stats = FrameRenderer(loaded).render(bake(loaded, [0]).frame(0))[1]
print(json.dumps({"variant": mi.variant(), "compiled": stats.kernels_compiled}))
"""


def _env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "MOTION_EXECUTOR"}
    return {**env, "MOTION_CACHE_DIR": str(tmp_path / "cache"), "DRJIT_CACHE_DIR": str(tmp_path / "cache" / "kernels")}


def _cold_frame(env: dict[str, str], junk: str) -> dict[str, object]:
    res = subprocess.run([sys.executable, "-c", _COLD_FRAME, str(SCENE), junk], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_garbage_the_collector_has_not_reached_compiles_no_kernel(tmp_path: Path) -> None:
    """A worker whose process holds an unreachable Mitsuba instance when its cold frame
    starts replays the kernels another process compiled (it compiled one more: the flake
    of test_cache_warm_makes_a_ci_jobs_first_frame_warm)."""
    env = _env(tmp_path)
    first = _cold_frame(env, "clean")
    if str(first["variant"]).startswith("scalar"):
        pytest.skip("the scalar fallback compiles no kernels")
    assert first["compiled"] > 0
    assert _cold_frame(env, "junk")["compiled"] == 0


def test_cache_warm_renders_the_jobs_frames_and_twice_adds_nothing(tmp_path: Path) -> None:
    """`cache warm --preset ci-smoke` renders the preset's own frames (it rendered frame 0
    only); a second warm compiles nothing and adds no kernel file; the job on two worker
    processes (each one's first frame cold, at another frame) compiles none."""
    env = _env(tmp_path)
    kernels = tmp_path / "cache" / "kernels"

    def warm() -> tuple[int, set[str]]:
        res = subprocess.run([MOTION, "cache", "warm", str(SCENE), "--preset", "ci-smoke"], capture_output=True, text=True, env=env, timeout=300)
        assert res.returncode == 0, res.stderr
        assert "(frames 0,24,47)" in res.stdout, res.stdout
        return int(res.stdout.split("kernels: ")[1].split()[0]), {p.name for p in kernels.iterdir()}

    compiled, files = warm()
    assert compiled > 0 and any(f.endswith(".bin") for f in files)
    again, files_again = warm()
    # Known, not fixed: the broadphase's per-frame buffer write (render/kernel/broadphase.py) is
    # one tiny kernel in two variants, as drjit's recycled variable indices order its two
    # buffers, and a process meets one of them only (per process, not per write: 16 writes
    # in one process met one). So a second warm may add that one file, outside the frames'
    # counted kernels, about one run in five (seen at e7ddd83 too). Anything more is a
    # kernel the warm-up missed.
    assert again == 0 and files <= files_again and len(files_again - files) <= 1, sorted(files_again - files)
    job = subprocess.run([MOTION, "render", str(SCENE), "--preset", "ci-smoke", "-o", str(tmp_path / "out"), "--workers", "2", "--no-progress"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert job.returncode == 0, job.stderr
    rows = report(tmp_path / "out")["frames"]
    assert sum(1 for r in rows if r.get("cold")) == 2
    assert [(r["frame"], r.get("kernels_compiled")) for r in rows] == [(0, 0), (24, 0), (47, 0)]


def test_cache_warm_makes_a_ci_jobs_first_frame_warm(tmp_path: Path) -> None:
    """`motion cache warm SCENE --preset P` compiles the job's kernels into a fresh cache;
    the job then compiles none; `motion cache key` names what the cache depends on."""
    env = _auto({"MOTION_CACHE_DIR": str(tmp_path / "cache"), "DRJIT_CACHE_DIR": str(tmp_path / "cache" / "kernels")})
    key = subprocess.run([MOTION, "cache", "key"], capture_output=True, text=True, env=env, timeout=60)
    assert key.returncode == 0 and key.stdout.startswith("motion-kernels-") and str(tmp_path / "cache" / "kernels") in key.stdout
    warm = subprocess.run([MOTION, "cache", "warm", str(SCENE), "--preset", "ci-smoke"], capture_output=True, text=True, env=env, timeout=300)
    assert warm.returncode == 0, warm.stderr
    assert "motion-warm-" not in warm.stdout + warm.stderr  # no path in the folder it removes
    compiled = int(warm.stdout.split("kernels: ")[1].split()[0])
    assert compiled > 0, warm.stdout
    job = subprocess.run([MOTION, "render", str(SCENE), "--preset", "ci-smoke", "-o", str(tmp_path / "out"), "--no-progress"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert job.returncode == 0, job.stderr
    rows = report(tmp_path / "out")["frames"]
    assert sum(int(r.get("kernels_compiled") or 0) for r in rows) == 0, [(r["frame"], r.get("worker"), r.get("cold"), r.get("kernels_compiled")) for r in rows]
