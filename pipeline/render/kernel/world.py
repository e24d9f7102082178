"""The scene a path meets at its own time, for the `motion_path` integrator: the static
set (one `mi.Scene`, its BVH never rebuilt) and everything that moves, rigidly, as
particles or deforming (one broadphase and one atlas, walked in ONE symbolic loop).

`intersect` finds the nearest hit over all of them and returns it in world space;
`occluded` answers a shadow ray against the same set at the same time. Rigid movers,
particles and deforming meshes cost the kernel the same trace sites whatever their number
(docs/rendering.md, "One traversal for everything that moves"):

1. the broadphase (render/kernel/broadphase.py): one ellipsoid per mover or particle holding it
   across the shutter, in the engine's own BVH; the walk visits the ellipsoids a ray
   enters, in order, from `reach` behind its origin up to the nearest hit found so far;
2. for each one entered, the exact test at the lane's own time: the proxy's pose at u
   (a mover's slerped pose, a particle's lerped centre; a deforming mesh's template by
   `Movers.template_of`), its posed bounding sphere, then
   the ray in the template's rest frame, moved to its cell of the atlas
   (render/kernel/atlas.py), clipped to the cell's box, and traced there.

All scenes are traced in one kernel: on CUDA they must share one SBT owner (render/kernel/sbt.py),
which `check_shared` verifies before each render, on every variant.
"""

from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from .lights import MovingEmitters
from ..poses.kernel import Movers, may_hit
from .sbt import SbtOwner, check_shared

NONE = 0xFFFFFFFF  # `hit` of a ray that met nothing that moves
TRACES: list[str] = []  # every trace site this process has traced into a kernel (`trace`)


def trace(kind: str, scene: mi.Scene, ray: Any, active: Any, preliminary: bool = False) -> Any:
    """The one place a kernel traces a scene: `kind` is "intersect" or "occluded". Each
    call while a kernel is traced is one trace site in it; `TRACES` counts them, so a test
    can check that the count does not grow with the scene."""
    TRACES.append(kind)
    if kind == "occluded":
        return scene.ray_test(ray, active)
    if preliminary:
        return scene.ray_intersect_preliminary(ray, coherent=False, active=active)
    return scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=active)


def segment_in_box(o: Any, d: Any, lo: Any, hi: Any, maxt: Any) -> tuple[Any, Any]:
    """The part [t0, t1] of the ray segment o + t d, t in [0, maxt], inside the box
    (lo, hi), by the slab test; empty where t0 > t1. A zero component of d becomes a huge
    finite inverse, never inf * 0."""
    inv = dr.rcp(dr.select(dr.abs(d) < 1e-30, dr.select(d < 0, -1e-30, 1e-30), d))
    ta, tb = (lo - o) * inv, (hi - o) * inv
    t0 = dr.maximum(dr.max(dr.minimum(ta, tb)), 0.0)
    t1 = dr.minimum(dr.min(dr.maximum(ta, tb)), maxt)
    return t0, t1


class World:
    """The geometry of one job besides the static scene: the broadphase and atlas of
    everything that moves, and the sampler of the emitters on it (render/kernel/lights.py)."""

    def __init__(self) -> None:
        self.broadphase: mi.Scene | None = None  # render/kernel/broadphase.py
        self.atlas: mi.Scene | None = None  # render/kernel/atlas.py
        self.rigid = 0  # rigid movers, deforming meshes' movers included (proxies 0 .. rigid - 1)
        self.particles = 0  # particle capacity (proxies rigid .. rigid + particles - 1)
        self.emitters: MovingEmitters | None = None  # the emitters on things that move (lights.py)
        self.owner: SbtOwner | None = None  # the SBT owner of every scene traced (render/kernel/sbt.py)
        self._checked: tuple[int, ...] | None = None  # the set of scenes `check_shared` last passed

    @property
    def moving(self) -> bool:
        """Whether anything is in the broadphase."""
        return self.rigid + self.particles > 0 and self.broadphase is not None and self.atlas is not None

    def traced(self, scene: mi.Scene) -> list[mi.Scene]:
        """Every scene one kernel traces: the static `scene`, the broadphase and atlas."""
        return [scene, *([self.broadphase, self.atlas] if self.moving else [])]  # type: ignore[list-item]

    def set_owner(self, owner: SbtOwner | None) -> None:
        """The SBT owner every traced scene was built against (render/kernel/sbt.py)."""
        self.owner = owner
        self._checked = None

    def check_shared(self, scene: mi.Scene) -> None:
        """Raise `sbt.SbtOwnerError` unless the scenes traced with the static `scene`
        share one SBT owner that covers their shape types (render/kernel/sbt.py); checked again
        only when the set of scenes changed."""
        traced = self.traced(scene)
        key = (id(self.owner), *map(id, traced))
        if key != self._checked:  # once per set of scenes, not per frame
            check_shared(traced, self.owner)
            self._checked = key

    def set_moving(self, broadphase: mi.Scene | None, atlas: mi.Scene | None, rigid: int, particles: int, emitters: MovingEmitters | None = None) -> None:
        """The broadphase and atlas scenes, the counts of rigid movers (deforming meshes'
        movers included) and particles they hold, and the sampler of the emitters on
        them (None where nothing that moves emits)."""
        self.broadphase, self.atlas = broadphase, atlas
        self.rigid, self.particles = rigid, particles
        self.emitters = emitters if emitters is not None and len(emitters) else None
        self._checked = None

    # --- the traversal of everything that moves --------------------------------------------

    def _cell_ray(self, movers: Movers, k: Any, ray: Any, active: Any, maxt: Any) -> tuple[Any, Any, Any, Any]:
        """Proxy k's exact test, up to the trace: (the ray in its template's atlas cell,
        clipped to the cell's box and starting at its entry; that entry's distance t0 along
        the world ray; whether there is anything to trace; the proxy's pose at u)."""
        pose, template, exists = movers.proxy(k, active)
        near = may_hit(movers.template_sphere(template, pose, exists), ray, exists, maxt)
        offset, lo, hi = movers.template_box(template, near)
        local = pose.ray_to_rest(ray)
        o = local.o + offset
        d = local.d
        t0, t1 = segment_in_box(o, d, lo, hi, maxt)
        ok = near & (t0 <= t1)
        cell = mi.Ray3f(ray)
        cell.o = o + d * t0
        cell.d = d
        cell.maxt = dr.maximum(t1 - t0, 0.0)
        return cell, t0, ok, pose

    def _walk(self, movers: Movers, ray: Any, active: Any, state: tuple[Any, ...], visit: Any, maxt_of: Any) -> tuple[Any, ...]:
        """The broadphase walk: from `reach` behind the ray's origin, each ellipsoid entry in
        order, `visit(k, state, live)` for the proxy k entered; stops where the next entry
        lies beyond `maxt_of(state)` (the nearest hit so far, or the shadow ray's end) or
        `visit` clears the lane."""
        reach = self.reach(movers)
        start = ray.o - ray.d * reach
        # the part of the line from `start` inside the box holding every live proxy
        # (`broadphase.union_box`, padded for float32)
        lo = movers.data.vec("proxy_box", 3, mi.UInt32(0), True)
        hi = movers.data.vec("proxy_box", 3, mi.UInt32(1), True)
        t_in, t_out = segment_in_box(start, ray.d, lo, hi, dr.inf)
        # a lane whose segment [0, maxt] (from its origin, `reach` past the start) misses
        # that box meets no proxy: no walk (a conservative gate)
        active = active & (dr.maximum(t_in, reach) <= dr.minimum(t_out, reach + maxt_of(state)))
        # the lane walks its own part of the shutter's proxies, in that part's region
        # (render/kernel/broadphase.py `in_regions`), only inside the box, so that it never
        # reaches another region
        count = movers.data.scalar("regions", mi.UInt32(0), True)
        spacing = movers.data.scalar("regions", mi.UInt32(1), True)
        part = dr.minimum(mi.UInt32(dr.floor(dr.clip(movers.u, 0.0, 1.0) * count)), mi.UInt32(count) - 1)
        shift = mi.Vector3f(mi.Float(part) * spacing, 0.0, 0.0)
        first = part * (self.rigid + self.particles)

        def cond(t_b: Any, live: Any, *rest: Any) -> Any:
            return live

        def body(t_b: Any, live: Any, *rest: Any) -> tuple[Any, ...]:
            probe = mi.Ray3f(ray)
            probe.o = start + shift + ray.d * t_b
            probe.maxt = dr.maximum(dr.minimum(reach + maxt_of(rest), t_out) - t_b, 0.0)
            pb = trace("intersect", self.broadphase, probe, live, preliminary=True)
            found = live & pb.is_valid()
            rest, live_after = visit(mi.UInt32(pb.prim_index) - first, rest, found)
            entered = t_b + pb.t
            # past this entry (never 0: an ellipsoid just entered is not entered again), by
            # more than float32 rounds the walk's distance and the probe's coordinates (a
            # part's region lies up to B spacings from the origin: a step under their
            # rounding would leave the probe where it was, and the walk would crawl)
            step = dr.maximum(dr.maximum(entered * 2e-7, dr.max(dr.abs(probe.o)) * 2.4e-7), 1e-7)
            t_b = dr.select(found, entered + step, t_b)
            return (t_b, found & live_after, *rest)

        out = dr.while_loop((mi.Float(t_in), mi.Bool(active), *state), cond, body, labels=("t_b", "live", *(f"s{i}" for i in range(len(state)))), label="broadphase")
        return tuple(out[2:])

    def reach(self, movers: Movers) -> Any:
        """How far behind a ray its broadphase walk starts (render/kernel/broadphase.py `reach`)."""
        return movers.data.scalar("reach", mi.UInt32(0), True)

    def _nearest_moving(self, movers: Movers, ray: Any, active: Any, nearest: Any) -> tuple[Any, Any, Any, Any]:
        """The nearest hit on anything that moves closer than `nearest`: (its preliminary
        intersection in the atlas, its distance, the proxy index or NONE, the distance t0 of
        its cell entry)."""
        state = (dr.zeros(mi.PreliminaryIntersection3f), mi.Float(nearest), mi.UInt32(NONE), mi.Float(0.0))

        def visit(k: Any, st: tuple[Any, ...], live: Any) -> tuple[tuple[Any, ...], Any]:
            best, near_t, hit, hit_t0 = st
            cell, t0, ok, _ = self._cell_ray(movers, k, ray, live, near_t)
            pi = trace("intersect", self.atlas, cell, ok, preliminary=True)
            t = pi.t + t0
            closer = ok & pi.is_valid() & (t < near_t)
            return (dr.select(closer, pi, best), dr.select(closer, t, near_t), dr.select(closer, k, hit), dr.select(closer, t0, hit_t0)), live

        best, near_t, hit, hit_t0 = self._walk(movers, ray, active, state, visit, lambda st: st[1])
        return best, near_t, hit, hit_t0

    # --- the queries --------------------------------------------------------------------------

    def intersect(self, scene: mi.Scene, ray: mi.Ray3f, movers: Movers, active: Any) -> tuple[Any, Any, Any]:
        """Nearest hit over all scenes, in world space; whether it is on something that
        moves; and which proxy (`hit`: a rigid mover below `movers.rigid`, a particle
        above; NONE for the static scene). `movers`: the movers at the path's time."""
        si = trace("intersect", scene, ray, active)
        on_mover = mi.Bool(False)
        hit = mi.UInt32(NONE)
        if not self.moving:
            return si, on_mover, hit
        nearest = dr.select(si.is_valid(), si.t, dr.inf)
        best, _, proxy, t0 = self._nearest_moving(movers, ray, active, nearest)
        won = active & (proxy != NONE)

        # the winner's surface interaction, in its atlas cell, moved to world space: a
        # branch, so packets in which no lane hit anything moving skip it
        def surface(si: Any) -> Any:
            pose, template, _ = movers.proxy(dr.select(won, proxy, 0), won)
            offset = movers.template_box(template, won)[0]
            local = pose.ray_to_rest(ray)
            cell = mi.Ray3f(local)
            cell.o = local.o + offset + local.d * t0  # the traversal's cell ray, as traced
            cell.maxt = dr.inf
            si_m = best.compute_surface_interaction(cell, mi.RayFlags.All, won)
            si_m.t = si_m.t + t0
            si_m.p = si_m.p - offset
            return dr.select(won, pose.surface_to_world(si_m), si)

        si = dr.if_stmt((si,), won, surface, lambda si: si, label="moving_surface")
        return si, on_mover | won, dr.select(won, proxy, hit)

    def occluded(self, scene: mi.Scene, ray: mi.Ray3f, movers: Movers, active: Any) -> Any:
        """Whether a shadow ray is blocked by any scene at the path's time."""
        hit = trace("occluded", scene, ray, active)
        if not self.moving:
            return hit

        def visit(proxy: Any, st: tuple[Any, ...], live: Any) -> tuple[tuple[Any, ...], Any]:
            (blocked,) = st
            cell, _, ok, _ = self._cell_ray(movers, proxy, ray, live, ray.maxt)
            blocked |= trace("occluded", self.atlas, cell, ok)
            return (blocked,), live & ~blocked

        (blocked,) = self._walk(movers, ray, active & ~hit, (mi.Bool(False),), visit, lambda st: ray.maxt)
        return hit | blocked

