"""The scene a path meets at its own time, for the `motion_path` integrator: the static
set (one `mi.Scene`, its BVH never rebuilt), everything that moves rigidly or as particles
(one broadphase and one atlas, walked in ONE symbolic loop), and the time-sliced deforming
meshes (render/slices.py: one scene per baked sample, a path sees the slice nearest its
time).

`intersect` finds the nearest hit over all of them and returns it in world space;
`occluded` answers a shadow ray against the same set at the same time. Rigid movers and
particles cost the kernel the same trace sites whatever their number
(docs/rendering.md, "One traversal for everything that moves"):

1. the broadphase (render/broadphase.py): one ellipsoid per mover or particle holding it
   across the shutter, in the engine's own BVH; the walk visits the ellipsoids a ray
   enters, in order, from `reach` behind its origin up to the nearest hit found so far;
2. for each one entered, the exact test at the lane's own time: the proxy's pose at u
   (a mover's slerped pose, a particle's lerped centre), its posed bounding sphere, then
   the ray in the template's rest frame, moved to its cell of the atlas
   (render/atlas.py), clipped to the cell's box, and traced there.

All scenes are traced in one kernel: on CUDA they must share one SBT owner (render/sbt.py),
which `check_shared` verifies before each render, on every variant.
"""

from __future__ import annotations

from typing import Any, Sequence

import drjit as dr
import mitsuba as mi

from .poses import Movers, may_hit
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
    movers and particles, the emissive movers' own scenes, and the slice groups."""

    def __init__(self) -> None:
        self.broadphase: mi.Scene | None = None  # render/broadphase.py
        self.atlas: mi.Scene | None = None  # render/atlas.py
        self.rigid = 0  # rigid movers (proxies 0 .. rigid - 1)
        self.particles = 0  # particle capacity (proxies rigid .. rigid + particles - 1)
        self.emitters: dict[int, mi.Scene] = {}  # emissive mover -> its rest-frame scene (emitter sampling)
        self.particle_emitters: list[tuple[int, int, mi.Scene]] = []  # emissive particle systems: (first particle, room, holder scene)
        self.slices: list[list[mi.Scene]] = []  # per deforming object: one scene per shutter sample
        self.emissive_slices: list[int] = []  # indices of slice groups that carry area emitters
        self.owner: SbtOwner | None = None  # the SBT owner of every scene traced (render/sbt.py)
        self._checked: tuple[int, ...] | None = None  # the set of scenes `check_shared` last passed

    @property
    def emissive(self) -> list[int]:
        """Indices of the rigid movers that carry area emitters."""
        return sorted(self.emitters)

    @property
    def moving(self) -> bool:
        """Whether anything is in the broadphase."""
        return self.rigid + self.particles > 0 and self.broadphase is not None and self.atlas is not None

    def traced(self, scene: mi.Scene) -> list[mi.Scene]:
        """Every scene one kernel traces: the static `scene`, the broadphase and atlas, the
        emissive movers' scenes, every slice."""
        moving = [self.broadphase, self.atlas] if self.moving else []
        holders = [h for _, _, h in self.particle_emitters]
        return [scene, *moving, *(self.emitters[k] for k in self.emissive), *holders, *(s for group in self.slices for s in group)]  # type: ignore[list-item]

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

    def set_moving(self, broadphase: mi.Scene | None, atlas: mi.Scene | None, rigid: int, particles: int, emitters: dict[int, mi.Scene],
                   particle_emitters: Sequence[tuple[int, int, mi.Scene]] = ()) -> None:
        """The broadphase and atlas scenes, the counts of rigid movers and particles they
        hold, the emissive movers' rest-frame scenes, and for each emissive particle system
        its particles' range (first, room) and its holder sphere's own scene."""
        self.broadphase, self.atlas = broadphase, atlas
        self.rigid, self.particles = rigid, particles
        self.emitters = dict(emitters)
        self.particle_emitters = list(particle_emitters)
        self._checked = None

    def sample_particle_emitter(self, system: int, movers: Movers, si: Any, sample1: Any, sample2: Any, active: Any) -> tuple[Any, Any]:
        """An emitter sample of emissive particle system `system` at the path's time: one of
        its particle slots chosen uniformly (a slot dead at that time gives nothing), a
        point of that sphere sampled by solid angle from si (its holder's own sampling, the
        sphere moved to the particle's centre). (DirectionSample3f in world space with the
        slot's choice in its pdf, weight)."""
        first, room, holder = self.particle_emitters[system]
        slot = dr.minimum(mi.UInt32(sample1 * room), room - 1)
        centre, alive = movers.particle(slot + first, active)
        ok = active & alive
        ref = mi.Interaction3f(si.t, si.time, si.wavelengths, si.p - centre, si.n)
        ds, weight = holder.sample_emitter_direction(ref, sample2, False, ok)
        ds.p = ds.p + centre
        ds.pdf = ds.pdf / room
        return ds, dr.select(ok, weight * room, 0.0)

    def particle_emitter_pdf(self, ds: Any, ref: Any, hit: Any, movers: Movers, pdf: Any, active: Any) -> Any:
        """The solid-angle pdf with which `sample_particle_emitter` would have chosen the
        point a BSDF-sampled ray hit on an emissive particle (`pdf` elsewhere)."""
        for first, room, holder in self.particle_emitters:
            base = self.rigid + first
            mine = active & (hit >= base) & (hit < base + room)
            centre, _ = movers.particle(dr.select(mine, hit - self.rigid, 0), mine)
            local_ref = mi.Interaction3f(ref.t, ref.time, ref.wavelengths, ref.p - centre, ref.n)
            local = mi.DirectionSample3f(ds.p - centre, ds.n, ds.uv, ds.time, ds.pdf, ds.delta, ds.d, ds.dist, ds.emitter)
            pdf = dr.select(mine, holder.pdf_emitter_direction(local_ref, local, mine) / room, pdf)
        return pdf

    def set_slices(self, groups: Sequence[Sequence[mi.Scene]]) -> None:
        """For each deforming object, one world-space scene per slice."""
        self.slices = [list(g) for g in groups]
        self._checked = None
        self.emissive_slices = [k for k, g in enumerate(self.slices) if g and len(g[0].emitters()) > 0]

    def slice_hit(self, group: int) -> int:
        """The `hit` value of a hit on slice group `group`: below `NONE`, above any proxy."""
        return NONE - 1 - group

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
        # (render/broadphase.py `in_regions`), only inside the box, so that it never
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
        """How far behind a ray its broadphase walk starts (render/broadphase.py `reach`)."""
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

    def intersect(self, scene: mi.Scene, ray: mi.Ray3f, movers: Movers, active: Any, k: Any) -> tuple[Any, Any, Any]:
        """Nearest hit over all scenes, in world space; whether it is on something that
        moves or a slice; and what it is (`hit`): a proxy index (a rigid mover below
        `movers.rigid`, a particle above), `slice_hit(g)` for an emissive slice group, NONE
        otherwise. `movers`: the movers at the path's time; k: its slice."""
        si = trace("intersect", scene, ray, active)
        on_mover = mi.Bool(False)
        hit = mi.UInt32(NONE)
        for g, group in enumerate(self.slices):
            for s, slice_scene in enumerate(group):
                mine = active & (k == s)
                si_s = trace("intersect", slice_scene, ray, mine)
                closer = mine & si_s.is_valid() & (si_s.t < si.t)
                si = dr.select(closer, si_s, si)
                on_mover |= closer
                if g in self.emissive_slices:
                    hit = dr.select(closer, mi.UInt32(self.slice_hit(g)), hit)
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

    def occluded(self, scene: mi.Scene, ray: mi.Ray3f, movers: Movers, active: Any, k: Any) -> Any:
        """Whether a shadow ray is blocked by any scene at the path's time."""
        hit = trace("occluded", scene, ray, active)
        for group in self.slices:
            for s, slice_scene in enumerate(group):
                hit |= trace("occluded", slice_scene, ray, active & ~hit & (k == s))
        if not self.moving:
            return hit

        def visit(proxy: Any, st: tuple[Any, ...], live: Any) -> tuple[tuple[Any, ...], Any]:
            (blocked,) = st
            cell, _, ok, _ = self._cell_ray(movers, proxy, ray, live, ray.maxt)
            blocked |= trace("occluded", self.atlas, cell, ok)
            return (blocked,), live & ~blocked

        (blocked,) = self._walk(movers, ray, active & ~hit, (mi.Bool(False),), visit, lambda st: ray.maxt)
        return hit | blocked

