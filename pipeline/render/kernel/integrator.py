"""`motion_path`: a unidirectional path tracer (BSDF + emitter sampling with MIS, Russian
roulette) in which every camera sample carries its own time inside the shutter.

Mitsuba 3 has no animated shapes, so motion is ours (docs/rendering.md):

* The static set lives in one `mi.Scene` whose BVH is built once per worker and never
  touched again. Rigid movers, particles and deforming meshes are reached through one
  broadphase walk and one atlas of rest-frame shapes, whatever their number; the scene queries over all of
  them at a path's time are `world.World`'s.
* The sensor's shutter is fixed to [0, 1]: `ray.time` is the sample's shutter fraction u,
  drawn by the sampler (stratified across a pixel's samples).
* At u, each mover's world_from_object = T(u) R(u) is interpolated from the baked samples
  across the shutter (`poses.FrameData`: translation linearly, rotation by slerp, never a
  matrix lerp). The ray is mapped into the mover's rest frame by the inverse, intersected
  there, and the nearest hit over all scenes wins; the hit is mapped back to world space.
* Shadow rays and every bounce of a path reuse the path's u: one path, one time.
* The camera's motion inside the shutter moves primary rays by C(u) C(frame)^-1.
* Lights that move (point, spot, directional: `set_lights`) are Mitsuba's own emitters
  queried in their rest frame at the path's time u, like movers; the emitters on things
  that move (movers, particles, deforming meshes) are one sampler over the atlas
  (`lights.MovingEmitters`), combined with BSDF sampling by MIS.
* The static scene's emitters are chosen by estimated contribution at each vertex, and a
  constant environment is reached by BSDF sampling only (`lights.py`).
* Per-frame data (poses) are one opaque drjit array of a fixed size, so a new frame
  replays the compiled kernels instead of compiling new ones.
* The image comes from our deterministic film (`film.py`); the AOV channels follow the
  AOV table (`aovs.py`).
"""

from __future__ import annotations

from typing import Any, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from . import aovs as aov_table
from . import film
from .lights import LightChoice, MovingEmitters, Posed
from .broadphase import EMPTY_BOX
from ..poses.kernel import FrameData, KernelPose, Movers
from .world import NONE, World


def _mis(a: Any, b: Any) -> Any:
    """Power heuristic (beta = 2); 0 where it is not finite (an infinite pdf, e.g. a light
    sampled from a point on its own plane, contributes nothing)."""
    a2 = dr.square(a)
    w = a2 / (a2 + dr.square(b))
    return dr.detach(dr.select(dr.isfinite(w), w, 0.0))


class MotionPathIntegrator(mi.SamplingIntegrator):
    """See the module docstring. Properties: max_depth (default 8), rr_depth (5), aovs
    (comma-separated names of the AOV table, `aovs.py`)."""

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 8))
        self.rr_depth = int(props.get("rr_depth", 5))
        self.aovs = [a for a in str(props.get("aovs", "")).split(",") if a]
        self._projection = ("perspective", 1.0, 0.0, 0.0)  # kind, scale (px per unit), cx, cy
        self.world = World()
        self.frame_data = FrameData()
        self.lights: list[tuple[bool, Any]] = []  # moving lights: (at infinity, emitter in its rest frame)
        self.choice: LightChoice | None = None  # light selection among the static scene's emitters (lights.py)
        self.rows: tuple[int, int] = (0, 1)  # (offset, step) of the image rows drawn: a field's with --fields (set_rows)

    # --- per-job and per-frame state --------------------------------------------------

    def release(self) -> None:
        """Drop the job's state: the scenes the kernel traces besides the scene that holds
        this integrator, and their SBT owner, which holds that scene too. The scene holds
        the integrator from C++, where Python's collector cannot see the edge, so that
        cycle would keep every scene and its JIT variables of a finished job alive; and
        every later kernel in the process traces the leaked plugins' calls (12 small
        renders made the next one 2.8x slower). render/worker/scene_cache.py calls it when the
        job's scene cache is freed. Plain references only: no drjit value is made here
        (the per-frame array holds no scene, and a finaliser may run late)."""
        self.world = World()
        self.lights = []
        self.choice = None

    def set_samples(self, n_samples: int) -> None:
        """The number of baked samples across the shutter (fixed for a job)."""
        self.frame_data.n_samples = max(2, int(n_samples))

    def set_moving(self, broadphase: Any, atlas: Any, rigid: int, particles: int, emitters: MovingEmitters | None = None) -> None:
        """Everything that moves (render/kernel/world.py): the broadphase and atlas scenes, how
        many rigid movers (deforming meshes' movers included) and particles they hold, and
        the sampler of the emitters on them (lights.py)."""
        self.world.set_moving(broadphase, atlas, rigid, particles, emitters)

    def set_sbt_owner(self, owner: Any) -> None:
        """The SBT owner every traced scene of the job was built against (render/kernel/sbt.py)."""
        self.world.set_owner(owner)

    def set_lights(self, lights: Sequence[Any]) -> None:
        """The lights that move (fixed for a job): delta emitters (point, spot, directional)
        built in the light's own frame (at the origin, shining along +Z) with unit intensity;
        poses and colours come per frame (`set_frame`). One at infinity (directional) casts
        its shadow ray along the sampled direction, the others to the sampled point."""
        self.lights = [(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite), e) for e in lights]
        self.choice = None  # the selection holds them: made again

    def set_rows(self, rows: tuple[int, int]) -> None:
        """The image rows the next renders draw (offset, step): (0, 1) every row, (0, 2) the
        top field, (1, 2) the bottom field (film.render)."""
        self.rows = (int(rows[0]), int(rows[1]))

    def set_projection(self, kind: str, scale: float, width: int, height: int) -> None:
        """Camera projection for the motion AOV: perspective scale = (W/2) / tan(xfov/2),
        orthographic scale = W / ortho_width (pixels per metre). Fixed for a job."""
        self._projection = (kind, float(scale), width / 2.0, height / 2.0)

    def set_frame(
        self,
        mover_translation: np.ndarray,
        mover_rotation: np.ndarray,
        camera_translation: np.ndarray,
        camera_rotation_rel: np.ndarray,
        sensor_origin: np.ndarray,
        camera_rotation: np.ndarray | None = None,
        light_translation: np.ndarray | None = None,
        light_rotation: np.ndarray | None = None,
        light_color: np.ndarray | None = None,
        moving: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Per-frame poses. mover_*: [M, N, 3|4]; camera_*: [N, 3|4], where the camera
        rotation is relative to the sensor's (C(u) C(frame)^-1); sensor_origin: [3];
        light_*: [L, N, 3|4] world_from_light across the shutter and light_color [L, 3]
        (the moving lights of `set_lights`, in order); `moving`: the atlas's templates and
        the particles (`mover_template` [M, 2] (first template, count; default: mover k
        draws template k), `template_offset` [T, 3], `template_box` [T, 2, 3],
        `template_sphere` [T, 4], `particle_p` [C, N, 3], `particle_alive` [C, N],
        `particle_template` [C], `reach` [1], `proxy_box` [2, 3], `regions` [2]; render/worker/scene_cache.py). A shape other than
        these is a `FrameDataError`."""
        m, n, nl = self.world.rigid, self.frame_data.n_samples, len(self.lights)
        c = self.world.particles
        if camera_rotation is None:
            camera_rotation = camera_rotation_rel
        if light_translation is None:
            light_translation, light_rotation, light_color = np.zeros((0, n, 3)), np.zeros((0, n, 4)), np.zeros((0, 3))
        moving = moving or {}
        t = len(moving.get("template_offset", ()))
        self.frame_data.set(
            {
                "mover_t": (mover_translation, (m, n, 3)),
                "mover_q": (mover_rotation, (m, n, 4)),
                "mover_template": (moving.get("mover_template", np.stack([np.arange(m), np.ones(m)], axis=1)), (m, 2)),
                "camera_t": (camera_translation, (n, 3)),
                "camera_rel": (camera_rotation_rel, (n, 4)),
                "sensor_origin": (sensor_origin, (3,)),
                "camera_q": (camera_rotation, (n, 4)),
                "light_t": (light_translation, (nl, n, 3)),
                "light_q": (light_rotation, (nl, n, 4)),
                "light_rgb": (light_color, (nl, 3)),
                "template_offset": (moving.get("template_offset", np.zeros((0, 3))), (t, 3)),
                "template_box": (moving.get("template_box", np.zeros((0, 2, 3))), (t, 2, 3)),
                "template_sphere": (moving.get("template_sphere", np.zeros((0, 4))), (t, 4)),
                "particle_p": (moving.get("particle_p", np.zeros((0, n, 3))), (c, n, 3)),
                "particle_alive": (moving.get("particle_alive", np.zeros((0, n))), (c, n)),
                "particle_template": (moving.get("particle_template", np.zeros(0)), (c,)),
                "reach": (moving.get("reach", np.zeros(1)), (1,)),
                "proxy_box": (moving.get("proxy_box", EMPTY_BOX), (2, 3)),
                "regions": (moving.get("regions", np.array([1.0, 0.0])), (2,)),
            }
        )

    # --- lights at the path's time ---------------------------------------------------------

    def _each_light_term(self, scene: mi.Scene, si: Any, bsdf: Any, ctx: Any, choice: LightChoice, posed: Posed, movers: Movers, active: Any) -> Any:
        """Direct light at si from each of a few moving lights (`LightChoice.each`): one
        deterministic sample of each delta light (point, spot, directional) in its rest frame
        at the path's time, back in world space, its shadow ray tested against every scene at
        the same time; no MIS (BSDF sampling never reaches a delta light)."""
        L = mi.Spectrum(0.0)
        for index, at_infinity, emitter in choice.each:
            pose, colour = posed.poses[index], posed.colours[index]
            ds, weight = emitter.sample_direction(pose.interaction_to_rest(si), mi.Point2f(0.5), active)
            d = pose.vector_to_world(ds.d)
            shadow = si.spawn_ray(d) if at_infinity else si.spawn_ray_to(pose.point_to_world(ds.p))
            ok = active & (ds.pdf != 0.0)
            ok &= ~self.world.occluded(scene, shadow, movers, ok)
            value = bsdf.eval(ctx, si, si.to_local(d), ok)
            L += dr.select(ok, value * weight * colour, 0.0)
        return L

    def _moving_emitter_term(self, scene: mi.Scene, sampler: mi.Sampler, si: Any, bsdf: Any, ctx: Any, movers: Movers, active: Any) -> Any:
        """Direct light at si from the emitters on things that move (movers, particles,
        deforming meshes): one sample of one of them, whatever their number, in its atlas
        cell at the path's time (lights.py `MovingEmitters`), the shadow ray tested against
        every scene at the same time, MIS against BSDF sampling."""
        emitters = self.world.emitters
        if emitters is None:
            return mi.Spectrum(0.0)
        ds, weight = emitters.sample(movers, si, sampler.next_1d(), sampler.next_2d(), active)
        ok = active & (ds.pdf != 0.0)
        ok &= ~self.world.occluded(scene, si.spawn_ray_to(ds.p), movers, ok)
        value, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), ok)
        mis = dr.select(ds.delta, 1.0, _mis(ds.pdf, bsdf_pdf))
        return dr.select(ok, mis * value * weight, 0.0)

    def _choice(self, scene: mi.Scene) -> LightChoice:
        """The light selection among `scene`'s emitters and the moving lights, made once
        per scene (and again when the moving lights are set)."""
        if self.choice is None or self.choice.scene_id != id(scene):
            self.choice = LightChoice(scene, self.lights)
        return self.choice

    def _posed(self, light_poses: list[KernelPose], active: Any) -> Posed:
        """The moving lights at the path's time: poses and colours (`lights.Posed`)."""
        colours = []
        for index in range(len(self.lights)):
            rgb = self.frame_data.vec("light_rgb", 3, mi.UInt32(index), active)
            colours.append(mi.Spectrum(rgb.x, rgb.y, rgb.z))
        return Posed(light_poses, colours)

    # --- AOVs of the first hit (the table: aovs.py) ----------------------------------------

    def _project(self, p: Any, record: int, active: Any) -> Any:
        """Pixel coordinates of world point p seen by the camera at shutter sample `record`."""
        kind, scale, cx, cy = self._projection
        local = self.frame_data.sample_pose("camera_t", "camera_q", record, active).point_to_rest(p)  # camera space: +Z forward, +Y up, +X left
        if kind == "orthographic":
            x, y = local.x * scale, local.y * scale
        else:
            z = dr.maximum(local.z, 1e-6)
            x, y = local.x / z * scale, local.y / z * scale
        return mi.Vector2f(cx - x, cy - y)

    def _motion_vector(self, si: Any, hit: Any, movers: Movers, active: Any) -> Any:
        """Screen-space motion of the first hit across the shutter, in pixels: a point on
        a mover or a particle follows it from the first baked sample to the last."""
        last = self.frame_data.n_samples - 1
        p0, p1 = mi.Vector3f(si.p), mi.Vector3f(si.p)
        if movers.total:
            mine = active & (hit < movers.total)
            index = dr.select(mine, hit, 0)
            rest = movers.proxy(index, mine)[0].point_to_rest(si.p)
            p0 = dr.select(mine, movers.proxy_at_sample(index, 0, mine).point_to_world(rest), p0)
            p1 = dr.select(mine, movers.proxy_at_sample(index, last, mine).point_to_world(rest), p1)
        v = self._project(p1, last, active) - self._project(p0, 0, active)
        return dr.select(si.is_valid(), v, 0.0)

    def _albedo(self, scene: mi.Scene, si: Any, ray: Any, active: Any) -> Any:
        """First-hit albedo, the denoiser's guide (OIDN's convention): the BSDF's diffuse
        reflectance; 1 on purely specular surfaces (mirror, glass), which have none; on
        emitters and where the ray leaves the scene, the emitted radiance clamped to [0, 1]."""
        bsdf = si.bsdf(ray)
        diffuse = mi.Color3f(bsdf.eval_diffuse_reflectance(si, active))
        specular = ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        surface = dr.select(si.is_valid() & specular, mi.Color3f(1.0), diffuse)
        emitter = si.emitter(scene, active)
        glow = dr.clip(mi.Color3f(emitter.eval(si, active & (emitter != None))), 0.0, 1.0)  # noqa: E711
        lit = (emitter != None) | ~si.is_valid()  # noqa: E711
        return dr.select(lit, glow, surface)

    # --- steps of the path (`sample`); each traces the same operations, in the same order,
    # as when they were written inline, so the kernel is unchanged -------------------------

    def _primary_ray(self, ray: mi.RayDifferential3f, ci: Any, cf: Any, active: Any) -> mi.Ray3f:
        """The camera's motion inside the shutter, C(u) C(frame)^-1, applied to the primary
        ray (ci, cf: the shutter segment of u, `FrameData.segment`)."""
        data = self.frame_data
        camera = data.pose("camera_t", "camera_rel", 0, ci, cf, active)
        cam_origin = data.vec("sensor_origin", 3, mi.UInt32(0), active)
        ray = mi.Ray3f(ray)
        ray.o = camera.point_to_world(ray.o - cam_origin)
        ray.d = camera.vector_to_world(ray.d)
        return ray

    def _aov_zeros(self) -> dict[str, Any]:
        """The computed AOVs' starting values, only those asked for: none asked, none carried
        through the path loop."""
        zeros = {"depth": mi.Float(0.0), "normal": mi.Vector3f(0.0), "motion": mi.Vector2f(0.0), "albedo": mi.Color3f(0.0)}
        return {a.name: zeros[a.name] for a in aov_table.computed(self.aovs)}

    def _first_hit_aovs(
        self, aov: dict[str, Any], scene: mi.Scene, si: Any, ray: Any, data: FrameData, ci: Any, cf: Any, hit_mover: Any, movers: Movers, depth: Any, active: Any
    ) -> dict[str, Any]:
        """`aov` with the lanes whose path is at its first vertex set to that vertex's
        values (the others keep theirs)."""
        first = active & (depth == 0) & si.is_valid()
        if "depth" in aov:
            # camera-space depth along the view axis, with the camera at this time
            view = data.pose("camera_t", "camera_q", 0, ci, cf, first)
            aov["depth"] = dr.select(first, view.point_to_rest(si.p).z, aov["depth"])
        if "normal" in aov:
            aov["normal"] = dr.select(first, si.sh_frame.n, aov["normal"])
        if "motion" in aov:
            aov["motion"] = dr.select(first, self._motion_vector(si, hit_mover, movers, first), aov["motion"])
        if "albedo" in aov:
            # misses count too: they see the environment (or nothing)
            primary = active & (depth == 0)
            aov["albedo"] = dr.select(primary, self._albedo(scene, si, ray, primary), aov["albedo"])
        return aov

    def _emission_hit(
        self, scene: mi.Scene, si: Any, prev_si: Any, prev_bsdf_pdf: Any, prev_bsdf_delta: Any, on_mover: Any, hit_mover: Any, choice: LightChoice, posed: Posed, movers: Movers, depth: Any
    ) -> tuple[Any, Any]:
        """The direction sample of the emitter a BSDF-sampled segment reached, and its MIS
        weight against emitter sampling of the same emitter: the static scene's (chosen by
        `choice`), or one on something that moves (`MovingEmitters.pdf`, in its atlas cell
        at the path's time). 1 on the first segment."""
        ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
        em_pdf = dr.select(~prev_bsdf_delta & ~on_mover, choice.pdf(prev_si, ds, posed, ~prev_bsdf_delta & ~on_mover), 0.0)
        if self.world.emitters is not None:  # on something that moves: the moving emitters' sampler
            mine = ~prev_bsdf_delta & on_mover & (hit_mover != NONE) & (ds.emitter != None)  # noqa: E711
            em_pdf = dr.select(mine, self.world.emitters.pdf(movers, prev_si, ds, hit_mover, mine), em_pdf)
        return ds, dr.select(depth == 0, 1.0, _mis(prev_bsdf_pdf, em_pdf))

    def _light_term(
        self, scene: mi.Scene, sampler: mi.Sampler, si: Any, bsdf: Any, bsdf_ctx: Any, choice: LightChoice, posed: Posed, movers: Movers, beta: Any, active_next: Any
    ) -> Any:
        """Emitter sampling of the static scene's lights and the moving lights (one chosen
        by contribution: lights.py), the shadow ray tested across all scenes at the path's
        time, MIS against BSDF sampling (a delta light: none); weighted by the path
        throughput `beta`."""
        active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds_em, em_weight, at_infinity = choice.sample(scene, si, posed, sampler.next_1d(), sampler.next_2d(), active_em)
        active_em &= ds_em.pdf != 0.0
        # a moving light at infinity (directional): along its direction, unbounded
        shadow = dr.select(at_infinity, si.spawn_ray(ds_em.d), si.spawn_ray_to(ds_em.p))
        occluded = self.world.occluded(scene, shadow, movers, active_em)
        active_em &= ~occluded
        wo = si.to_local(ds_em.d)
        bsdf_val, bsdf_pdf = bsdf.eval_pdf(bsdf_ctx, si, wo, active_em)
        mis_em = dr.select(ds_em.delta, 1.0, _mis(ds_em.pdf, bsdf_pdf))
        return dr.select(active_em, beta * mis_em * bsdf_val * em_weight, 0.0)

    # --- the path ------------------------------------------------------------------------

    @dr.syntax
    def sample(
        self,
        scene: mi.Scene,
        sampler: mi.Sampler,
        ray: mi.RayDifferential3f,
        medium: mi.Medium | None = None,
        active: mi.Bool = True,
    ) -> tuple[mi.Spectrum, mi.Bool, list[mi.Float]]:
        """One path per lane at the lane's shutter fraction `ray.time`: its radiance,
        whether its first segment met anything (or an environment), and its AOV channels
        in the table's order (`aovs.channel_names(self.aovs)`)."""
        u = mi.Float(ray.time)  # shutter fraction in [0, 1]
        data = self.frame_data
        ci, cf = data.segment(u)
        ray = self._primary_ray(ray, ci, cf, active)

        movers = Movers(data, self.world.rigid, self.world.particles, u, active)
        light_poses = data.poses("light_t", "light_q", len(self.lights), u, active)
        choice = self._choice(scene)
        posed = self._posed(light_poses, active)
        has_choice = len(choice) > 0  # a Python bool: @dr.syntax keeps it a plain `if`
        bsdf_ctx = mi.BSDFContext()
        L = mi.Spectrum(0.0)
        beta = mi.Spectrum(1.0)
        depth = mi.UInt32(0)
        eta = mi.Float(1.0)
        active = mi.Bool(active)
        prev_si = dr.zeros(mi.SurfaceInteraction3f)
        prev_bsdf_pdf = mi.Float(1.0)
        prev_bsdf_delta = mi.Bool(True)
        valid = mi.Bool(False)
        aov = self._aov_zeros()
        want_aovs = len(aov) > 0  # a Python bool: @dr.syntax keeps it a plain `if`

        while dr.hint(active, max_iterations=self.max_depth, label="motion_path"):
            si, on_mover, hit_mover = self.world.intersect(scene, ray, movers, active)
            valid |= active & si.is_valid() & (depth == 0)
            if want_aovs:
                aov = self._first_hit_aovs(aov, scene, si, ray, data, ci, cf, hit_mover, movers, depth, active)
            # emission reached by BSDF sampling, MIS-weighted against emitter sampling of the
            # same emitter
            ds, mis_bsdf = self._emission_hit(scene, si, prev_si, prev_bsdf_pdf, prev_bsdf_delta, on_mover, hit_mover, choice, posed, movers, depth)
            L += beta * mis_bsdf * ds.emitter.eval(si, active & (prev_bsdf_pdf > 0))

            active_next = active & si.is_valid() & (depth + 1 < self.max_depth)
            bsdf = si.bsdf(ray)

            # emitter sampling (the static lights, and the moving ones past a few, one chosen
            # by contribution: lights.py), shadow test across all scenes at time u
            if has_choice:
                L += self._light_term(scene, sampler, si, bsdf, bsdf_ctx, choice, posed, movers, beta, active_next)
            # a few moving lights, each; the emitters on things that move, one of them; at
            # this path's time u
            lit = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            L += beta * self._each_light_term(scene, si, bsdf, bsdf_ctx, choice, posed, movers, lit)
            L += beta * self._moving_emitter_term(scene, sampler, si, bsdf, bsdf_ctx, movers, lit)

            # BSDF sampling: the next segment of the path
            bs, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(), sampler.next_2d(), active_next)
            ray = si.spawn_ray(si.to_world(bs.wo))
            beta *= bsdf_weight
            eta *= bs.eta
            prev_si = dr.detach(si, True)
            prev_bsdf_pdf = bs.pdf
            prev_bsdf_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)

            # Russian roulette on the throughput (with the refraction scale removed)
            depth[si.is_valid()] += 1
            q = dr.minimum(dr.max(beta) * dr.square(eta), 0.99)
            rr = depth >= self.rr_depth
            beta[rr] *= dr.rcp(q)
            active = active_next & (~rr | (sampler.next_1d() < q)) & (dr.max(beta) != 0)

        if scene.environment() is not None:
            valid = mi.Bool(True)
        channels: list[Any] = [c for a in aov_table.computed(self.aovs) for c in ([aov[a.name]] if a.name == "depth" else list(aov[a.name]))]
        return L, valid, channels

    # --- the image --------------------------------------------------------------------

    def render(
        self,
        scene: mi.Scene,
        sensor: Any = 0,
        seed: Any = 0,
        spp: int = 0,
        develop: bool = True,
        evaluate: bool = True,
    ) -> Any:
        """Render to an image whose bits do not depend on the thread count (`film.render`).
        Returns [H, W, 4 + AOV channels] (RGBA, alpha = the pixel's coverage)."""
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        self.world.check_shared(scene)  # one SBT for the whole kernel, or no render (render/kernel/sbt.py)
        # the path loop's state holds read-only locals (@dr.syntax passes every local the
        # body reads): with OptimizeLoops drjit would drop them and trace the body again,
        # every frame; LLVM folds them as well
        self._choice(scene)  # before tracing: it may evaluate (an environment's irradiance)
        with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
            return film.render(self.sample, scene, sensor, seed, spp, self.rows)

    def aov_names(self) -> list[str]:
        """The EXR channel names of the AOV channels after RGBA (`aovs.channel_names`)."""
        return aov_table.channel_names(self.aovs)

    def to_string(self) -> str:
        """Mitsuba's description of the integrator."""
        return f"MotionPathIntegrator[max_depth={self.max_depth}, movers={self.world.rigid}, particles={self.world.particles}]"


_registered = False


def register() -> None:
    """Make `{"type": "motion_path"}` available to mi.load_dict (once per process)."""
    global _registered
    if not _registered:
        mi.register_integrator("motion_path", lambda props: MotionPathIntegrator(props))
        _registered = True
