"""Light sampling of the `motion_path` integrator, in one home: which light a path vertex
samples, and with what probability (docs/rendering.md, "Light selection"). Three kinds:
the static scene's emitters and, past `EACH_MAX` of them, the moving lights, in one choice
by contribution (`LightChoice`, the moving ones posed at the path's time: `Posed`); up to
`EACH_MAX` moving lights each sampled at every vertex (`LightChoice.each`); and the
emitters on everything that moves, one sampler over the atlas (`MovingEmitters`).

Mitsuba's `path` picks one of the scene's emitters uniformly, with the first coordinate of
the light sample reused, and samples a constant sky over the whole sphere: with a sun and a
sky, half of the shadow rays go to the sky and half of those below the horizon. Here:

* A **constant environment is never light-sampled**, nor a smooth map (peak radiance below
  `SMOOTH_ENV` times the mean): BSDF sampling reaches it (with MIS weight 1, since no
  other strategy produces it), which for a diffuse surface is exactly cosine-weighted,
  the ideal strategy for a uniform sky.
* The other emitters are chosen in proportion to an **estimate of their contribution at
  the shading point**: the luminance of the emitter's own deterministic sample (u = 0.5:
  exact irradiance for a point, spot or directional light; radiance times solid angle of
  the centre for an area light) times the cosine with the shading normal on the side the
  path came from; an environment map counts its mean irradiance. A defensive share
  (`DEFENSIVE` of the probability, spread evenly) keeps every emitter's probability above
  zero wherever it could contribute (normal maps, transmission, parts of a large lamp
  above the horizon while its centre is below), so the estimator stays unbiased.
* The choice has its own sampler dimension (`next_1d`), the point on the light its own
  2D one: the choice never shares a dimension with the light's position, so both stay
  stratified across a pixel's samples.

The probability is a deterministic function of the shading point, so the BSDF strategy's
MIS weight at an emitter hit recomputes it at the previous vertex (`pdf`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

# share of the selection probability spread evenly over the candidates (defensive mixture)
DEFENSIVE = 0.1
# directions used once per job to estimate an environment map's irradiance and peak
ENV_PROBES = 1024
# an environment map whose brightest direction is below this many times its mean radiance
# is smooth: BSDF sampling reaches it better than light samples spread over the sphere
SMOOTH_ENV = 2.0


def _kind(emitter: Any) -> str:
    """Mitsuba's class name of an emitter (`ConstantBackgroundEmitter`, `AreaLight` ...)."""
    return str(emitter).split("[", 1)[0].strip()


def _env_stats(emitter: Any) -> tuple[float, float]:
    """An environment map's mean irradiance on a plane, (1/4) of the integral of its
    luminance over the sphere (pi times the mean radiance), by its own importance sampling;
    and its peak-to-mean radiance over the same directions (1 for a uniform map)."""
    it = dr.zeros(mi.Interaction3f)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(7, ENV_PROBES)
    ds, weight = emitter.sample_direction(it, sampler.next_2d(), True)
    lum = np.array(mi.luminance(weight))
    radiance = lum * np.array(ds.pdf)
    mean = float(np.mean(lum)) / (4.0 * np.pi)  # integral / 4 pi: the mean radiance
    peak = float(np.max(radiance)) / mean if mean > 0 else 1.0
    return float(np.mean(lum)) / 4.0, peak


class Posed(NamedTuple):
    """The moving lights at a path's time: each one's world_from_light (`poses.KernelPose`)
    and colour (mi.Spectrum), in the order the integrator was given them."""

    poses: list[Any]
    colours: list[Any]


# Up to this many moving lights, each is sampled at every vertex (its own shadow ray); more
# join the choice among the static emitters (one shadow ray for all). A delta light's sample
# is exact but for visibility: on bench_equal_error's `lamps` shot (lamps flying over
# terrain that shadows them) sampling each lamp reached relMSE 1e-4 in 0.122 s against
# 0.183 s chosen (4 lamps), 0.385 s against 0.403 s (16), and 5e-5 in 0.59 s against 0.99 s
# (16); a choice keeps the kernel's size and shadow rays bounded for a shot of many.
EACH_MAX = 16


class LightChoice:
    """The light-sampled emitters of one job and their selection at a vertex: the static
    scene's emitters and, past `EACH_MAX` of them, the moving lights (delta emitters built in
    their own frame, posed at the path's time: `Posed`), one candidate each, chosen by
    estimated contribution; up to `EACH_MAX` moving lights are `each`: sampled every one
    at every vertex (the integrator's `_each_light_term`)."""

    def __init__(self, scene: mi.Scene, moving: list[tuple[bool, Any]] | None = None) -> None:
        # the scene's id, not the scene: the integrator (which keeps this) is the scene's
        # own, and a reference back would be a cycle through C++ that keeps scenes alive
        self.scene_id = id(scene)
        lights = [(k, infinite, emitter) for k, (infinite, emitter) in enumerate(moving or [])]  # (index in `Posed`, at infinity, emitter in its rest frame)
        self.each = lights if len(lights) <= EACH_MAX else []
        self.moving = [] if self.each else lights
        emitters = list(scene.emitters())
        # a constant or smooth environment is reached by BSDF sampling only
        chosen = []
        for i, e in enumerate(emitters):
            if _kind(e) == "ConstantBackgroundEmitter":
                continue
            env = mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) and not mi.has_flag(e.flags(), mi.EmitterFlags.DeltaDirection)
            irradiance, peak = _env_stats(e) if env else (0.0, 0.0)
            if env and peak < SMOOTH_ENV:
                continue
            chosen.append((i, e, env, irradiance))
        self.emitters = [e for _, e, _, _ in chosen]
        self.scene_index = [i for i, _, _, _ in chosen]
        self.infinite = [env for _, _, env, _ in chosen]
        self.env_irradiance = [irr for _, _, _, irr in chosen]

    def __len__(self) -> int:
        return len(self.emitters) + len(self.moving)

    def _probabilities(self, si: Any, posed: Posed, active: Any) -> list[Any]:
        """Each candidate's selection probability at si (summing to 1): the static
        emitters', then the moving lights'."""
        k = len(self)
        if k == 1:
            return [mi.Float(1.0)]
        n = si.sh_frame.n * dr.select(si.wi.z < 0, -1.0, 1.0)  # the side the path came from
        estimates = []
        for emitter, infinite, env in zip(self.emitters, self.infinite, self.env_irradiance):
            if infinite:
                estimates.append(mi.Float(env))
                continue
            ds, weight = emitter.sample_direction(si, mi.Point2f(0.5), active)
            cos = dr.maximum(dr.dot(ds.d, n), 0.0)
            estimates.append(dr.select(ds.pdf > 0, mi.luminance(weight) * cos, 0.0))
        for index, _, emitter in self.moving:
            pose, colour = posed.poses[index], posed.colours[index]
            ds, weight = emitter.sample_direction(pose.interaction_to_rest(si), mi.Point2f(0.5), active)
            cos = dr.maximum(dr.dot(pose.vector_to_world(ds.d), n), 0.0)
            estimates.append(dr.select(ds.pdf > 0, mi.luminance(weight * colour) * cos, 0.0))
        total = estimates[0]
        for e in estimates[1:]:
            total = total + e
        share = DEFENSIVE / k
        scale = dr.select(total > 0, (1.0 - DEFENSIVE) / total, 0.0)
        uniform = dr.select(total > 0, share, 1.0 / k)
        return [dr.detach(uniform + e * scale) for e in estimates]

    def sample(self, scene: mi.Scene, si: Any, posed: Posed, u: Any, sample2: Any, active: Any) -> tuple[Any, Any, Any]:
        """One emitter sample at si: u (1D) picks the emitter, sample2 (2D) the point on it.
        Returns Mitsuba's (DirectionSample3f, weight = radiance / pdf) with the selection
        folded into both, as `Scene.sample_emitter_direction` returns them (no visibility
        test), and whether the light is a moving one at infinity (its shadow ray goes
        along the direction, unbounded)."""
        probs = self._probabilities(si, posed, active)
        index = mi.UInt32(0)
        prob = mi.Float(probs[0])
        cdf = mi.Float(0.0)
        for i, p in enumerate(probs[:-1]):
            cdf = cdf + p
            past = u >= cdf
            index = dr.select(past, i + 1, index)
            prob = dr.select(past, probs[i + 1], prob)
        count = len(self.emitters)
        ds, weight = dr.zeros(mi.DirectionSample3f), mi.Spectrum(0.0)
        if count:
            static = active & (index < count)
            table = mi.UInt32(self.scene_index)
            emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), dr.gather(mi.UInt32, table, dr.minimum(index, count - 1), static), static)
            ds, weight = emitter.sample_direction(si, sample2, static)
        at_infinity = mi.Bool(False)
        for j, (k, infinite, emitter) in enumerate(self.moving):
            pose, colour = posed.poses[k], posed.colours[k]
            mine = active & (index == count + j)
            ds_j, w_j = emitter.sample_direction(pose.interaction_to_rest(si), sample2, mine)
            ds_j.p, ds_j.n, ds_j.d = pose.point_to_world(ds_j.p), pose.vector_to_world(ds_j.n), pose.vector_to_world(ds_j.d)
            ds, weight = dr.select(mine, ds_j, ds), dr.select(mine, w_j * colour, weight)
            at_infinity |= mine & infinite
        ds.pdf *= prob
        weight *= dr.select(prob > 0, dr.rcp(prob), 0.0)
        return ds, weight, at_infinity

    def pdf(self, si: Any, ds: Any, posed: Posed, active: Any) -> Any:
        """The solid-angle pdf with which `sample` at si produces the emitter point of ds
        (0 for an emitter that is not light-sampled: a constant environment; a moving light
        is a delta light, never reached)."""
        if not self.emitters:
            return mi.Float(0.0)
        probs = self._probabilities(si, posed, active)
        prob = mi.Float(0.0)
        for emitter, p in zip(self.emitters, probs):
            prob = dr.select(ds.emitter == mi.EmitterPtr(emitter), p, prob)
        direction_pdf = ds.emitter.pdf_direction(si, ds, active & (prob > 0))
        return dr.select(prob > 0, direction_pdf * prob, 0.0)


NONE = 0xFFFFFFFF  # no emitter (a template slot without one)


class MovingEmitters:
    """The emitters on everything that moves, in one sampler: emissive rigid movers,
    emissive particle systems and emissive deforming meshes (a flock's agents each) all
    wear their emitters on their templates in the atlas (render/kernel/atlas.py), so one code
    path samples any of them, whatever their number (docs/rendering.md, "Light sampling").

    An *entry* is an emissive shape of a mover, or an emissive particle system: (its first
    proxy, its room: 1, or the system's particle slots; the shape's slot in its template).
    A vertex picks one entry uniformly and, in a particle system, one slot uniformly (a
    dead particle gives nothing), poses that proxy at the path's time (`Movers.proxy`: a
    deforming mesh's template by the same dither as its hit), and samples its template's
    emitter in the template's atlas cell: pmf 1 / (entries x room)."""

    def __init__(self, atlas: Any, entries: list[tuple[int, int, int]], template_emitter: np.ndarray, template_room: np.ndarray) -> None:
        self.count = len(entries)
        table = np.asarray(entries, dtype=np.uint32).reshape(-1, 3)
        self.base, self.room, self.slot = (mi.UInt32(table[:, c]) for c in range(3))
        self.width = int(template_emitter.shape[1]) if template_emitter.ndim == 2 and template_emitter.shape[1] else 1
        self.emitter_of = mi.UInt32(np.asarray(template_emitter, dtype=np.uint32).ravel())
        self.template_room = mi.Float(np.asarray(template_room, dtype=np.float32))
        self.emitters = atlas.emitters_dr()
        for value in (self.base, self.room, self.slot, self.emitter_of, self.template_room):
            dr.make_opaque(value)

    def __len__(self) -> int:
        return self.count

    def sample(self, movers: Any, si: Any, u: Any, sample2: Any, active: Any) -> tuple[Any, Any]:
        """One emitter sample at si from the moving emitters: u (1D) picks the entry and the
        particle slot, sample2 (2D) the point. Returns (DirectionSample3f in world space with
        the pmf folded into its pdf, weight = radiance / pdf); no visibility test."""
        x = u * self.count
        e = dr.minimum(mi.UInt32(x), self.count - 1)
        base = dr.gather(mi.UInt32, self.base, e, active)
        room = dr.gather(mi.UInt32, self.room, e, active)
        slot = dr.gather(mi.UInt32, self.slot, e, active)
        j = dr.minimum(mi.UInt32((x - mi.Float(e)) * mi.Float(room)), room - 1)
        pose, template, exists = movers.proxy(base + j, active)
        index = dr.gather(mi.UInt32, self.emitter_of, template * self.width + slot, active & exists)
        ok = active & exists & (index != NONE)
        emitter = dr.gather(mi.EmitterPtr, self.emitters, index, ok)
        offset = movers.template_box(template, ok)[0]
        ref = pose.interaction_to_rest(si)
        ref.p = ref.p + offset
        ds, weight = emitter.sample_direction(ref, sample2, ok)
        ds.p = pose.point_to_world(ds.p - offset)
        ds.n = pose.vector_to_world(ds.n)
        ds.d = pose.vector_to_world(ds.d)
        pmf = dr.rcp(mi.Float(self.count) * mi.Float(room))
        ds.pdf = ds.pdf * pmf
        ok &= ds.pdf > 0
        return ds, dr.select(ok, weight / pmf, 0.0)

    def pdf(self, movers: Any, ref: Any, ds: Any, hit: Any, active: Any) -> Any:
        """The solid-angle pdf with which `sample` at ref would have produced the point of
        ds, a BSDF-sampled hit on proxy `hit` whose shape emits (ds from that hit, in world
        space)."""
        pose, template, _ = movers.proxy(dr.select(active, hit, 0), active)
        offset = movers.template_box(template, active)[0]
        local = pose.direction_sample_to_rest(ds)
        local.p = local.p + offset
        at = pose.interaction_to_rest(ref)
        at.p = at.p + offset
        room = dr.gather(mi.Float, self.template_room, template, active)
        return dr.select(active, ds.emitter.pdf_direction(at, local, active) / (mi.Float(self.count) * room), 0.0)


def moving_emitter_tables(atlas_keys: list[str], emitter_shapes: list[str], movers: list[int], particle_systems: list[tuple[int, int, int]],
                          templates: int) -> tuple[list[tuple[int, int, int]], np.ndarray, np.ndarray]:
    """The tables of `MovingEmitters` from the atlas: `atlas_keys` name each template's
    shapes (`<key>__<k>`), `emitter_shapes` the shape of each of the atlas's emitters in
    order; `movers`: each rigid proxy's first template (movers, then deforming meshes'
    movers); `particle_systems`: each system's (first proxy, room, holder template).
    Returns (entries, template_emitter [T, J], template_room [T])."""
    by_key = {key: t for t, key in enumerate(atlas_keys)}
    slots: dict[int, list[int]] = {}
    for index, shape in enumerate(emitter_shapes):
        key = shape.rsplit("__", 1)[0]
        if key in by_key:
            slots.setdefault(by_key[key], []).append(index)
    width = max((len(v) for v in slots.values()), default=1)
    table = np.full((templates, width), NONE, dtype=np.uint32)
    for t, indices in slots.items():
        table[t, :len(indices)] = indices
    room = np.ones(templates)
    entries = [(k, 1, j) for k, first in enumerate(movers) for j in range(len(slots.get(first, [])))]
    for first_proxy, count, holder in particle_systems:
        room[holder] = count
        entries += [(first_proxy, count, j) for j in range(len(slots.get(holder, [])))]
    return entries, table, room
