"""The worker's frame: one `FrameRenderer` per (scene, settings) in a worker process renders
every frame it is given, keeping what it can.

Under an LLVM or CUDA variant a frame goes through the first-frame cache
(render/worker/scene_cache.py: the scene built once on the cold frame, a warm frame changes only
what moved) and the motion_path integrator; under a scalar variant through the scalar
fallback (render/translate/scalar_fallback.py: Mitsuba's `path`, one whole scene per instant).
On LLVM and CUDA an engine warning that means wrong pixels fails the frame
(render/worker/engine_log.py). Either way the frame's seed depends only on the scene seed and
the frame (`frame_seed`), `motion_blur: subframes` is the mean of instants (`accumulate_subframes`),
the AOV channels are split into layers by the AOV table (render/kernel/aovs.py), and each frame
reports its stats: cold or warm, setup vs render seconds, kernels, cache hits.
"""

from __future__ import annotations

import gc
import hashlib
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

from ...bake import BakedFrame
from ...field_model import Parity, row_offset
from ...scene.loader import LoadedScene
from ..kernel.aovs import split_layers
from .engine_log import watching
from ..translate.roles import sort_scene
from ..translate.scalar_fallback import ScalarFallback
from .scene_cache import SceneCache
from ..poses.stacked import StackedFrame, stack_frame


@dataclass
class FrameStats:
    """What rendering one frame cost, and whether the worker's cache served it."""

    frame: int
    cold: bool
    setup_s: float
    render_s: float
    kernels_compiled: int
    kernels_reused: int
    asset_cache_hits: int
    scene_reused: bool
    updated_params: tuple[str, ...] = ()  # scene parameters changed for this frame


def frame_seed(seed: int, frame: int, policy: str) -> int:
    """Deterministic per-frame seed: the same for every worker that renders the frame."""
    if policy == "fixed":
        return int(seed)
    digest = hashlib.sha256(f"{seed}:{frame}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def accumulate_subframes(render_at: Callable[[float, int, int], Any], count: int, spp: int, seed: int) -> Any:
    """`motion_blur: subframes`: the mean of `count` images, each the whole scene at one
    instant, the centres of equal parts of the shutter (u = (j + 0.5) / count), with
    spp / count samples and its own seed. `render_at(u, seed, spp)` renders one instant."""
    per = max(1, spp // count)
    acc = None
    for j in range(count):
        img = render_at((j + 0.5) / count, (seed * 7919 + j) & 0x7FFFFFFF, per)
        acc = img if acc is None else acc + img
    return acc / count


@contextmanager
def _collector_held(cold: bool) -> Iterator[None]:
    """On a cold frame: collect garbage, then hold Python's collector until the frame's
    kernels are traced. A kernel's IR holds the registry ids of every live Mitsuba BSDF,
    shape and emitter of the process (the domains of its virtual calls): a stray instance
    in a reference cycle, or one the collector frees half way through the build (when it
    runs depends on allocation counts, which other threads move), gives the scene other
    ids and so a kernel `motion cache warm` never compiled."""
    if not cold:
        yield
        return
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _with_alpha(rgba: np.ndarray) -> np.ndarray:
    """An RGB image gets an opaque alpha channel; RGBA stays as it is."""
    if rgba.shape[2] == 3:
        return np.concatenate([rgba, np.ones(rgba.shape[:2] + (1,), np.float32)], axis=2)
    return rgba


class FrameRenderer:
    """Renders the frames of one scene in one worker process, keeping everything it can."""

    def __init__(self, loaded: LoadedScene, spp: int | None = None) -> None:
        import drjit as dr
        import mitsuba as mi

        from ..kernel.integrator import register

        register()
        self.loaded = loaded
        self.settings = loaded.scene.render
        self.spp = int(spp or self.settings.spp)
        # `integrator: direct` is direct lighting only: paths of one bounce
        self.max_depth = 2 if self.settings.integrator == "direct" else self.settings.max_depth
        self._dr = dr
        self._frames_done = 0
        # The motion_path integrator is vectorised drjit code: LLVM or CUDA variants only.
        # The scalar fallback renders with Mitsuba's own `path`, movers placed per sub-frame.
        self.vectorized = not mi.variant().startswith("scalar")
        roles = sort_scene(loaded)
        self.static_names, self.mover_names = roles.static_names, roles.mover_names
        self.particle_names = roles.particle_names
        self.deforming_names = roles.deforming_names
        self.moving_lights = roles.moving_lights
        self.cache = SceneCache(mi, dr, loaded, roles, self.spp, self.max_depth)
        self.fallback = ScalarFallback(mi, loaded, self.spp, self.max_depth)
        self._last_history: list[dict[str, Any]] = []
        dr.set_flag(dr.JitFlag.KernelHistory, True)

    @property
    def last_kernels(self) -> list[dict[str, Any]]:
        """The JIT kernels the last frame launched, in order (drjit's kernel history: `hash`,
        `size`, `cache_hit`, `execution_time` ...); one hash per kernel traced."""
        return self._last_history

    @property
    def _scene(self) -> Any:
        """The cached motion_path scene (None before the cold frame)."""
        return self.cache.scene

    def _full_scene(self, stacked: StackedFrame, u: float | None) -> Any:
        """The whole scene at one instant with Mitsuba's `path` (the scalar fallback's)."""
        return self.fallback.scene(stacked, u)

    def _full_scene_dict(self, stacked: StackedFrame, u: float | None) -> dict[str, Any]:
        """The Mitsuba dictionary of `_full_scene`."""
        return self.fallback.scene_dict(stacked, u)

    def _render_scalar(self, stacked: StackedFrame, mode: str, seed: int) -> Any:
        """A frame with the scalar fallback: the frame's instant for `off`, else sub-frames."""
        if mode == "off":
            return self.fallback.render_at(stacked, None, seed, self.spp)
        return accumulate_subframes(lambda u, s, n: self.fallback.render_at(stacked, u, s, n), self.settings.subframes, self.spp, seed)

    def _render_cached(self, stacked: StackedFrame, mode: str, seed: int, rows: tuple[int, int] = (0, 1)) -> Any:
        """A frame with the cached motion_path scene (built or updated already)."""
        if mode == "subframes":

            def render_at(u: float, s: int, n: int) -> Any:
                self.cache.set_frame(stacked, mode, u_fixed=u)
                return self.cache.render(s, n, rows)

            return accumulate_subframes(render_at, self.settings.subframes, self.spp, seed)
        self.cache.set_frame(stacked, mode)
        return self.cache.render(seed, self.spp, rows)

    def render(self, frame: BakedFrame, mode: str | None = None) -> tuple[np.ndarray, FrameStats]:
        """Render one baked frame; returns RGBA float32 [H, W, 4] and its stats
        (`render_layers` returns its AOV layers too)."""
        rgba, _, stats = self.render_layers(frame, mode)
        return rgba, stats

    def render_layers(self, frame: BakedFrame, mode: str | None = None, field: Parity | None = None) -> tuple[np.ndarray, dict[str, np.ndarray], FrameStats]:
        """Render one baked frame: RGBA float32 [H, W, 4], its AOV layers by name ([H, W, C]
        each; none unless the scene asks for them or denoises) and its stats. With `field`,
        only that field's rows (H / 2 of them): `motion render --fields`."""
        if field is None:
            return self._render(frame, mode)
        rgba, aovs, stats = self._render(frame, mode, (row_offset(field), 2))
        height = self.settings.resolution[1]

        def rows(image: np.ndarray) -> np.ndarray:
            # the scalar fallback renders every row: take the field's
            return image[row_offset(field) :: 2] if image.shape[0] == height else image

        return rows(rgba), {k: rows(v) for k, v in aovs.items()}, stats

    def _render(self, frame: BakedFrame, mode: str | None = None, rows: tuple[int, int] = (0, 1)) -> tuple[np.ndarray, dict[str, np.ndarray], FrameStats]:
        stacked = stack_frame(frame)
        from ..translate import assets

        dr = self._dr
        mode = mode or self.settings.motion_blur
        if not self.vectorized:
            t0 = time.perf_counter()
            seed = frame_seed(self.settings.seed, stacked.frame, self.settings.seed_policy)
            rgba = _with_alpha(np.array(self._render_scalar(stacked, mode, seed), dtype=np.float32))
            cold = self._frames_done == 0
            self._frames_done += 1
            return rgba, {}, FrameStats(stacked.frame, cold, 0.0, time.perf_counter() - t0, 0, 0, 0, False)
        hits0 = assets.STATS["hits"]
        t0 = time.perf_counter()
        cold = self.cache.scene is None
        updated: tuple[str, ...] = ()
        # an engine warning that means wrong pixels (a disabled trace on CUDA) fails the
        # frame (render/worker/engine_log.py)
        with watching() as engine, _collector_held(cold):
            if cold:
                self.cache.build(stacked, mode)
            else:
                updated = self.cache.update(stacked, mode)
            seed = frame_seed(self.settings.seed, stacked.frame, self.settings.seed_policy)
            dr.kernel_history()  # clear
            setup_s = time.perf_counter() - t0
            t1 = time.perf_counter()
            img = self._render_cached(stacked, mode, seed, rows)
            dr.eval(img)
            dr.sync_thread()
            rgba = np.array(img, dtype=np.float32)
            render_s = time.perf_counter() - t1
        engine.check()
        rgba, aovs = split_layers(rgba, self.cache.integrator.aovs)
        history = dr.kernel_history()
        self._last_history = [h for h in history if h.get("type") == dr.KernelType.JIT]
        compiled = sum(1 for h in history if h.get("type") == dr.KernelType.JIT and not h.get("cache_hit", False))
        reused = sum(1 for h in history if h.get("type") == dr.KernelType.JIT and h.get("cache_hit", False))
        rgba = _with_alpha(rgba)
        self._frames_done += 1
        return rgba, aovs, FrameStats(
            frame=stacked.frame,
            cold=cold,
            setup_s=setup_s,
            render_s=render_s,
            kernels_compiled=compiled,
            kernels_reused=reused,
            asset_cache_hits=assets.STATS["hits"] - hits0,
            scene_reused=not cold,
            updated_params=updated,
        )
