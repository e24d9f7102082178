"""The scene a path meets at its own time, for the `motion_path` integrator: the static
set (one `mi.Scene`, its BVH never rebuilt), the time-sliced groups of non-rigid geometry
(render/slices.py: one scene per baked sample, a path sees the slice nearest its time) and
the rigid movers (one rest-frame scene each, posed per path: render/poses.py).

`intersect` finds the nearest hit over all of them and returns it in world space;
`occluded` answers a shadow ray against the same set at the same time. All of them are
traced in one kernel: on CUDA they must share one SBT owner (render/sbt.py), which
`check_shared` verifies before each render, on every variant.
"""

from __future__ import annotations

from typing import Any, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from .poses import MoverTracks, bounding_spheres, may_hit
from .sbt import SbtOwner, check_shared


class World:
    """The geometry of one job besides the static scene: movers and slice groups."""

    def __init__(self) -> None:
        self.movers: list[mi.Scene] = []
        self.slices: list[list[mi.Scene]] = []  # per non-rigid object: one scene per shutter sample
        self.emissive: list[int] = []  # indices of movers that carry area emitters
        self.emissive_slices: list[int] = []  # indices of slice groups that carry area emitters
        self._spheres: tuple[list[tuple[float, ...]], np.ndarray] | None = None  # (boxes, spheres)
        self.owner: SbtOwner | None = None  # the SBT owner of every scene traced (render/sbt.py)
        self._checked: tuple[int, ...] | None = None  # the set of scenes `check_shared` last passed

    def traced(self, scene: mi.Scene) -> list[mi.Scene]:
        """Every scene one kernel traces: the static `scene`, the movers, every slice."""
        return [scene, *self.movers, *(s for group in self.slices for s in group)]

    def set_owner(self, owner: SbtOwner | None) -> None:
        """The SBT owner every traced scene was built against (render/sbt.py)."""
        self.owner = owner
        self._checked = None

    def check_shared(self, scene: mi.Scene) -> None:
        """Raise `sbt.SbtOwnerError` unless the scenes traced with the static `scene`
        share one SBT owner that covers their shape types (render/sbt.py); checked again
        only when the set of scenes changed."""
        traced = self.traced(scene)
        key = (id(self.owner), *map(id, traced))
        if key != self._checked:  # once per set of scenes, not per frame
            check_shared(traced, self.owner)
            self._checked = key

    def set_movers(self, movers: Sequence[mi.Scene]) -> None:
        """The rigid movers' rest-frame scenes (fixed for a job)."""
        self.movers = list(movers)
        self.emissive = [k for k, m in enumerate(self.movers) if len(m.emitters()) > 0]
        self._spheres = None
        self._checked = None

    def bounding_spheres(self) -> np.ndarray:
        """The movers' rest-frame bounding spheres [M, 4] (`poses.bounding_spheres`), made
        again only when a mover's box changed (a keyed scale): a mesh mover's sphere reads
        its vertices, which a warm frame need not do."""
        boxes = [tuple(np.array(b.min, dtype=float).ravel()) + tuple(np.array(b.max, dtype=float).ravel()) for b in (m.bbox() for m in self.movers)]
        if self._spheres is None or self._spheres[0] != boxes:
            self._spheres = (boxes, bounding_spheres(self.movers))
        return self._spheres[1]

    def set_slices(self, groups: Sequence[Sequence[mi.Scene]]) -> None:
        """For each deforming object or particle system, one world-space scene per slice."""
        self.slices = [list(g) for g in groups]
        self._checked = None
        self.emissive_slices = [k for k, g in enumerate(self.slices) if g and len(g[0].emitters()) > 0]

    def slice_hit(self, group: int) -> int:
        """The `hit_mover` value of a hit on slice group `group`: past the movers' indices
        and their "none" (len(movers)), so mover tests never match it."""
        return len(self.movers) + 1 + group

    def sample_slice_emitter(self, group: int, si: Any, sample: Any, k: Any, active: Any) -> tuple[Any, Any]:
        """An emitter direction sample from the emissive slice group `group` at the path's
        slice k (slices are in world space): (DirectionSample3f, weight)."""
        ds, weight = dr.zeros(mi.DirectionSample3f), mi.Spectrum(0.0)
        for s, slice_scene in enumerate(self.slices[group]):
            mine = active & (k == s)
            ds_s, w_s = slice_scene.sample_emitter_direction(si, sample, False, mine)
            ds, weight = dr.select(mine, ds_s, ds), dr.select(mine, w_s, weight)
        return ds, weight

    def slice_emitter_pdf(self, ds: Any, ref: Any, hit: Any, k: Any, pdf: Any, active: Any) -> Any:
        """The solid-angle pdf with which `sample_slice_emitter` would have chosen the
        emitter a BSDF-sampled ray hit on an emissive slice group (`pdf` elsewhere)."""
        for group in self.emissive_slices:
            for s, slice_scene in enumerate(self.slices[group]):
                mine = active & (hit == self.slice_hit(group)) & (k == s)
                pdf = dr.select(mine, slice_scene.pdf_emitter_direction(ref, ds, mine), pdf)
        return pdf

    def slice_of(self, u: Any) -> Any:
        """The time slice a path at shutter fraction u sees: the nearest of S slices
        (all groups have the same S)."""
        count = len(self.slices[0]) if self.slices else 1
        return mi.UInt32(dr.round(dr.clip(u, 0.0, 1.0) * (count - 1)))

    def intersect(self, scene: mi.Scene, ray: mi.Ray3f, movers: MoverTracks, active: Any, k: Any) -> tuple[Any, Any, Any]:
        """Nearest hit over all scenes, in world space; whether it is on a mover or a
        slice; and which mover (len(movers) for none). `movers`: the movers at the path's
        time; k: its slice."""
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=active)
        on_mover = mi.Bool(False)
        hit_mover = mi.UInt32(len(self.movers))
        for g, group in enumerate(self.slices):
            for s, slice_scene in enumerate(group):
                mine = active & (k == s)
                si_s = slice_scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=mine)
                closer = mine & si_s.is_valid() & (si_s.t < si.t)
                si = dr.select(closer, si_s, si)
                on_mover |= closer
                if g in self.emissive_slices:
                    hit_mover = dr.select(closer, mi.UInt32(self.slice_hit(g)), hit_mover)
        # movers: a preliminary hit per mover (traversal only, and only for rays that meet
        # its swept sphere and then its bounding sphere at their time); the surface
        # interaction of the nearest is computed once, in its rest frame, and moved to
        # world space
        nearest = dr.select(si.is_valid(), si.t, dr.inf)
        best = dr.zeros(mi.PreliminaryIntersection3f)
        for index, mover in enumerate(self.movers):
            # only up to the nearest hit so far: a mover whose sphere lies beyond it cannot be closer
            swept = may_hit(movers.swept(index), ray, active, nearest)

            def visit(best: Any, nearest: Any, hit_mover: Any, mover: Any = mover, index: int = index, swept: Any = swept) -> tuple[Any, Any, Any]:
                # posed at the lane's own time only past the swept sphere: the exact test
                pose = movers.pose(index)
                near = may_hit(movers.posed_sphere(index, pose), ray, swept, nearest)
                local = pose.ray_to_rest(ray)
                local.maxt = dr.minimum(local.maxt, nearest)
                pi = mover.ray_intersect_preliminary(local, coherent=False, active=near)
                closer = near & pi.is_valid() & (pi.t < nearest)
                return dr.select(closer, pi, best), dr.select(closer, pi.t, nearest), dr.select(closer, mi.UInt32(index), hit_mover)

            best, nearest, hit_mover = _if_any(swept, visit, (best, nearest, hit_mover))
        if self.movers:
            won = active & (hit_mover < len(self.movers))

            # a branch too: packets in which no lane hit a mover skip the winner's pose,
            # its surface interaction and the selects over the whole interaction
            def surface(si: Any) -> Any:
                pose = movers.pose(dr.select(won, hit_mover, 0))
                si_m = best.compute_surface_interaction(pose.ray_to_rest(ray), mi.RayFlags.All, won)
                return dr.select(won, pose.surface_to_world(si_m), si)

            si = _if_any(won, surface, (si,))
            on_mover |= won
        return si, on_mover, hit_mover

    def occluded(self, scene: mi.Scene, ray: mi.Ray3f, movers: MoverTracks, active: Any, k: Any) -> Any:
        """Whether a shadow ray is blocked by any scene at the path's time."""
        hit = scene.ray_test(ray, active)
        for group in self.slices:
            for s, slice_scene in enumerate(group):
                hit |= slice_scene.ray_test(ray, active & ~hit & (k == s))
        for index, mover in enumerate(self.movers):
            swept = may_hit(movers.swept(index), ray, active & ~hit)

            def test(hit: Any, mover: Any = mover, index: int = index, swept: Any = swept) -> Any:
                pose = movers.pose(index)
                near = may_hit(movers.posed_sphere(index, pose), ray, swept)
                return hit | mover.ray_test(pose.ray_to_rest(ray), near)

            hit = _if_any(swept, test, (hit,))
        return hit


def _if_any(cond: Any, body: Any, state: tuple[Any, ...]) -> Any:
    """`body(*state)` where `cond` holds, else the state unchanged, as a symbolic branch:
    on the LLVM backend a packet of lanes none of which meets a mover's swept sphere
    jumps over its pose, its rest-frame ray, its BVH call and the selects (and one in
    which no lane hit a mover, over the winner's surface interaction), so a frame pays
    for the movers its rays can hit, not for every mover on every ray (masked lanes alone
    would still compute all of it). The values are those of the masked code, bit for bit."""
    return dr.if_stmt(state, cond, body, lambda *unchanged: unchanged if len(unchanged) > 1 else unchanged[0], label="mover")
