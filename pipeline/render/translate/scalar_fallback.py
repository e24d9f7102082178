"""The scalar fallback: frames rendered with Mitsuba's own `path` integrator, one whole
scene per instant.

The motion_path integrator is vectorised drjit code and needs an LLVM or CUDA variant.
Under a scalar variant the worker builds the scene at one instant instead (every object
and light placed at the frame's time, or at one shutter fraction) and renders it with
`path`; motion blur is then the sub-frame comparison mode (the mean of instants, see
`frame_renderer.accumulate_subframes`). Particles are drawn as Mitsuba `ellipsoids` at
the instant, deforming meshes as one world-space mesh each, what the one traversal draws
at that instant (`instant.add_deforming`). Nothing is kept
between frames: this is the correctness fallback, not the fast path.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ...scene.loader import LoadedScene
from ...variant import load_dict
from .build import material_dict
from .instant import add_deforming, add_lights, add_particles, add_shapes, sensor_record

if TYPE_CHECKING:
    from ..poses.stacked import StackedFrame


class ScalarFallback:
    """Whole scenes at one instant with Mitsuba's `path` (any variant)."""

    def __init__(self, mi: Any, loaded: LoadedScene, spp: int, max_depth: int) -> None:
        self._mi = mi
        self.loaded = loaded
        self.spp = spp
        self.max_depth = max_depth

    def scene_dict(self, stacked: StackedFrame, u: float | None) -> dict[str, Any]:
        """The Mitsuba dictionary of the whole scene at the frame's time (u None) or at
        shutter fraction u: rigid objects, particles, deforming meshes and lights, Mitsuba's
        `path` integrator."""
        loaded = self.loaded
        scene = loaded.scene
        materials = {m.name: material_dict(m, loaded) for m in scene.materials}
        d: dict[str, Any] = {"type": "scene", "integrator": {"type": "path", "max_depth": self.max_depth, "rr_depth": scene.render.rr_depth}}
        d["sensor"] = sensor_record(loaded, self.spp, stacked, u)
        add_shapes(d, loaded, scene.objects, stacked, materials, u)
        add_particles(d, loaded, stacked, materials, u)
        add_deforming(d, loaded, stacked, materials, u)
        add_lights(d, loaded, stacked, u)
        return d

    def scene(self, stacked: StackedFrame, u: float | None) -> Any:
        """The loaded `mi.Scene` of `scene_dict`."""
        return load_dict(self.scene_dict(stacked, u))

    def render_at(self, stacked: StackedFrame, u: float | None, seed: int, spp: int) -> Any:
        """The image of the scene at one instant (u None: the frame's time)."""
        return self._mi.render(self.scene(stacked, u), seed=seed, spp=spp)
