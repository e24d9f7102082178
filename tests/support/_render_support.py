"""Render helpers for tests: a scene from YAML text, rendered in this process through the
real pipeline (bake -> BakedFrame -> FrameRenderer)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def activate() -> str:
    from motion.pipeline import variant

    return variant.activate("auto", quiet=True).variant


def load(tmp_path: Path, text: str, name: str = "scene.yaml") -> Any:
    from motion.pipeline.scene import load_scene

    path = tmp_path / name
    path.write_text(text)
    return load_scene(path)


def render(loaded: Any, frames: list[int], mode: str | None = None, renderer: Any = None) -> tuple[list[np.ndarray], list[Any], Any]:
    """Render `frames` with one (first-frame cached) renderer; returns images, stats, renderer."""
    activate()
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer
    from motion.pipeline.bake import evaluate_frames

    if renderer is None:
        # like a farm worker between jobs: free earlier scenes first. drjit traces virtual
        # calls over every LIVE instance (all BSDFs of all scenes), so scenes left alive by
        # other tests would change the compiled code and the last bit of the pixels.
        import gc

        gc.collect()
        renderer = FrameRenderer(loaded)
    images, stats = [], []
    for fi in evaluate_frames(loaded, frames):
        img, st = renderer.render(fi, mode)
        images.append(img)
        stats.append(st)
    return images, stats, renderer


def render_layers(loaded: Any, frame: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """One frame's RGBA and its AOV layers by name (a fresh renderer, like `render`)."""
    activate()
    import gc

    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.worker.frame_renderer import FrameRenderer

    gc.collect()
    (fi,) = evaluate_frames(loaded, [frame])
    rgba, aovs, _ = FrameRenderer(loaded).render_layers(fi)
    return rgba, aovs


def column_x(width: int, ortho_width: float) -> np.ndarray:
    """World x of each pixel column's centre for the tests' orthographic camera (at -z
    looking +z, up +y): camera +X is image left, so x falls from left to right."""
    pitch = ortho_width / width
    return ortho_width / 2 - (np.arange(width) + 0.5) * pitch
