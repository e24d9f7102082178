"""`motion_path`: a unidirectional path tracer (BSDF + emitter sampling with MIS, Russian
roulette) in which every camera sample carries its own time inside the shutter.

Mitsuba 3 has no animated shapes, so motion is ours (docs/motion-blur.md):

* The static set lives in one `mi.Scene` whose BVH is built once per worker and never
  touched again. Each rigid mover lives in its own tiny scene, in its rest frame.
* The sensor's shutter is fixed to [0, 1]: `ray.time` is the sample's shutter fraction u,
  drawn by the sampler (stratified across a pixel's samples).
* At u, each mover's world_from_object = T(u) R(u) is interpolated from the baked samples
  across the shutter: translation linearly, rotation by slerp (never a matrix lerp).
  The ray is mapped into the mover's rest frame by the inverse, intersected there, and
  the nearest hit over all scenes wins; the hit is mapped back to world space.
* Shadow rays and every bounce of a path reuse the path's u: one path, one time.
* The camera's motion inside the shutter moves primary rays by C(u) C(frame)^-1.
* Lights that move (point, spot, directional: `set_lights`) are Mitsuba's own emitters
  queried in their rest frame at the path's time u, like movers; emitters on movers are
  sampled in the mover's rest frame too, and combined with BSDF sampling by MIS.
* Per-frame data (poses) are opaque drjit arrays of a fixed size, so a new frame replays
  the compiled kernels instead of compiling new ones.
"""

from __future__ import annotations

import os
from typing import Any, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import RendererError

# The blocks of the per-frame data array, in order (see `set_frame`).
FRAME_BLOCKS = ("mover_t", "mover_q", "camera_t", "camera_rel", "sensor_origin", "camera_q", "light_t", "light_q", "light_rgb", "mover_sphere")


def _mis(a: Any, b: Any) -> Any:
    """Power heuristic (beta = 2); 0 where it is not finite (an infinite pdf, e.g. a light
    sampled from a point on its own plane, contributes nothing)."""
    a2 = dr.square(a)
    w = a2 / (a2 + dr.square(b))
    return dr.detach(dr.select(dr.isfinite(w), w, 0.0))


def _qrot(q: Any, v: Any) -> Any:
    """Rotate vector v by unit quaternion q = (w, x, y, z) stored as mi.Vector4f."""
    u = mi.Vector3f(q.y, q.z, q.w)
    w = q.x
    t = 2 * dr.cross(u, v)
    return v + w * t + dr.cross(u, t)


def _qconj(q: Any) -> Any:
    return mi.Vector4f(q.x, -q.y, -q.z, -q.w)


def _to_rest(ray: Any, t: Any, q: Any) -> Any:
    """The ray in the rest frame of a body posed at (t, q): mapped by the inverse rigid
    transform (lengths, and so ray parameters t, are kept)."""
    qi = _qconj(q)
    local = mi.Ray3f(ray)
    local.o = _qrot(qi, ray.o - t)
    local.d = _qrot(qi, ray.d)
    return local


def _slerp(q0: Any, q1: Any, f: Any) -> Any:
    """Shortest-arc spherical interpolation of unit quaternions (w, x, y, z)."""
    d = dr.dot(q0, q1)
    q1 = dr.select(d < 0, -q1, q1)
    d = dr.abs(d)
    theta = dr.acos(dr.minimum(d, 1.0))
    s = dr.sin(theta)
    small = s < 1e-4
    w0 = dr.select(small, 1 - f, dr.sin((1 - f) * theta) / s)
    w1 = dr.select(small, f, dr.sin(f * theta) / s)
    return dr.normalize(w0 * q0 + w1 * q1)


class MotionPathIntegrator(mi.SamplingIntegrator):
    """See the module docstring. Properties: max_depth (default 8), rr_depth (5)."""

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.max_depth = int(props.get("max_depth", 8))
        self.rr_depth = int(props.get("rr_depth", 5))
        # AOVs of the first hit: "depth" (Z), "normal" (N.X/Y/Z, world), "motion" (motion.X/Y:
        # screen pixels moved from shutter open to close, +x right, +y down), "albedo"
        # (albedo.R/G/B: the denoiser's guide, see `_albedo`)
        self.aovs = [a for a in str(props.get("aovs", "")).split(",") if a]
        self._projection = ("perspective", 1.0, 0.0, 0.0)  # kind, scale (px per unit), cx, cy
        self.movers: list[mi.Scene] = []
        self.slices: list[list[mi.Scene]] = []  # per non-rigid object: one scene per shutter sample
        self.n_samples = 2
        # All per-frame data live in ONE opaque array (offsets below are fixed for a job):
        # with several fresh arrays per frame, drjit recycles variable indices from two
        # frames back, their relative order flips and the kernel's input order with it,
        # which alternates between two kernel variants.
        self._frame_data = mi.Float(0.0)
        self._at: dict[str, int] = dict.fromkeys(FRAME_BLOCKS, 0)  # block name -> element offset
        self.lights: list[tuple[str, Any]] = []  # moving lights: (kind, emitter in its rest frame)
        self.emissive: list[int] = []  # indices of movers that carry area emitters

    # --- per-job and per-frame state --------------------------------------------------

    def set_movers(self, movers: Sequence[mi.Scene], n_samples: int) -> None:
        """The rest-frame scenes of the rigid movers (fixed for a job) and the number of
        baked samples across the shutter."""
        self.movers = list(movers)
        self.n_samples = max(2, int(n_samples))
        self.emissive = [k for k, m in enumerate(self.movers) if len(m.emitters()) > 0]

    def set_lights(self, lights: Sequence[tuple[str, Any]]) -> None:
        """The lights that move (fixed for a job): (kind, emitter) with kind `point`, `spot` or
        `directional` and the emitter built in the light's own frame (at the origin, shining
        along +Z) with unit intensity; poses and colours come per frame (`set_frame`)."""
        self.lights = list(lights)

    def set_projection(self, kind: str, scale: float, width: int, height: int) -> None:
        """Camera projection for the motion AOV: perspective scale = (W/2) / tan(xfov/2),
        orthographic scale = W / ortho_width (pixels per metre). Fixed for a job."""
        self._projection = (kind, float(scale), width / 2.0, height / 2.0)

    def set_slices(self, groups: Sequence[Sequence[mi.Scene]]) -> None:
        """Time-sliced geometry (render/slices.py): for each deforming object or particle
        system, one world-space scene per baked shutter sample."""
        self.slices = [list(g) for g in groups]

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
    ) -> None:
        """Per-frame poses. mover_*: [M, N, 3|4]; camera_*: [N, 3|4], where the camera
        rotation is relative to the sensor's (C(u) C(frame)^-1); sensor_origin: [3];
        light_*: [L, N, 3|4] world_from_light across the shutter and light_color [L, 3]
        (the moving lights of `set_lights`, in order). Each mover's bounding sphere in its
        rest frame (from its scene's box, which follows a per-frame scale) joins them."""
        m, n, nl = len(self.movers), self.n_samples, len(self.lights)
        if camera_rotation is None:
            camera_rotation = camera_rotation_rel
        if light_translation is None:
            light_translation, light_rotation, light_color = np.zeros((0, n, 3)), np.zeros((0, n, 4)), np.zeros((0, 3))
        blocks = {
            "mover_t": (mover_translation, (m, n, 3)),
            "mover_q": (mover_rotation, (m, n, 4)),
            "camera_t": (camera_translation, (n, 3)),
            "camera_rel": (camera_rotation_rel, (n, 4)),
            "sensor_origin": (sensor_origin, (3,)),
            "camera_q": (camera_rotation, (n, 4)),
            "light_t": (light_translation, (nl, n, 3)),
            "light_q": (light_rotation, (nl, n, 4)),
            "light_rgb": (light_color, (nl, 3)),
            "mover_sphere": (_spheres(self.movers), (m, 4)),
        }
        flat = []
        for name in FRAME_BLOCKS:
            value, shape = blocks[name]
            value = np.asarray(value, dtype=np.float32)
            if value.shape != shape:
                raise RendererError(f"frame data {name!r} has shape {value.shape}, expected {shape}")
            flat.append(value.ravel())
        # element offsets of each block; the gathers below index in units of 3 or 4 floats
        offsets = np.cumsum([0, *(len(a) for a in flat[:-1])])
        self._at = {name: int(o) for name, o in zip(FRAME_BLOCKS, offsets)}
        self._frame_data = mi.Float(np.concatenate(flat))
        # opaque: new values each frame must not become new literals in the kernel
        dr.make_opaque(self._frame_data)

    # --- pose lookups at the sample's time ---------------------------------------------

    def _segment(self, u: Any) -> tuple[Any, Any]:
        x = dr.clip(u, 0.0, 1.0) * (self.n_samples - 1)
        i = dr.minimum(mi.UInt32(dr.floor(x)), self.n_samples - 2)
        return i, x - mi.Float(i)

    def _vec(self, offset: int, width: int, j: Any, active: Any) -> Any:
        """Element j of the `width`-float records starting at `offset` in the frame data."""
        base = offset + j * width
        comps = [dr.gather(mi.Float, self._frame_data, base + c, active) for c in range(width)]
        return mi.Vector3f(*comps) if width == 3 else mi.Vector4f(*comps)

    def _pose(self, t_offset: int, q_offset: int, record: int, i: Any, f: Any, active: Any) -> tuple[Any, Any]:
        j = record + i
        t0 = self._vec(t_offset, 3, j, active)
        t1 = self._vec(t_offset, 3, j + 1, active)
        q0 = self._vec(q_offset, 4, j, active)
        q1 = self._vec(q_offset, 4, j + 1, active)
        return dr.lerp(t0, t1, f), _slerp(q0, q1, f)

    def _mover_poses(self, u: Any, active: Any) -> list[tuple[Any, Any]]:
        i, f = self._segment(u)
        mt, mq = self._at["mover_t"], self._at["mover_q"]
        return [self._pose(mt, mq, k * self.n_samples, i, f, active) for k in range(len(self.movers))]

    def _mover_spheres(self, poses: list[tuple[Any, Any]], active: Any) -> list[tuple[Any, Any]]:
        """Each mover's bounding sphere (world centre, squared radius) at the path's time."""
        out = []
        for index, (t, q) in enumerate(poses):
            s = self._vec(self._at["mover_sphere"], 4, mi.UInt32(index), active)
            out.append((_qrot(q, mi.Vector3f(s.x, s.y, s.z)) + t, dr.square(s.w)))
        return out

    def _light_poses(self, u: Any, active: Any) -> list[tuple[Any, Any]]:
        i, f = self._segment(u)
        lt, lq = self._at["light_t"], self._at["light_q"]
        return [self._pose(lt, lq, k * self.n_samples, i, f, active) for k in range(len(self.lights))]

    # --- scene queries over the static set and the movers --------------------------------

    def _slice_of(self, u: Any) -> Any:
        """The time slice a path at shutter fraction u sees: the nearest of S slices
        (all groups have the same S)."""
        count = len(self.slices[0]) if self.slices else 1
        return mi.UInt32(dr.round(dr.clip(u, 0.0, 1.0) * (count - 1)))

    @staticmethod
    def _may_hit(sphere: tuple[Any, Any], ray: mi.Ray3f, active: Any) -> Any:
        """Whether the ray meets a mover's bounding sphere (`_mover_spheres`, posed at the
        path's time): rays that miss it never pay for the mover's traversal."""
        centre, r2 = sphere
        oc = ray.o - centre
        a = dr.squared_norm(ray.d)
        b = dr.dot(oc, ray.d)
        disc = dr.square(b) - a * (dr.squared_norm(oc) - r2)
        root = dr.safe_sqrt(disc)
        # the segment [0, maxt] meets the sphere: roots (-b -+ root) / a straddle some of it
        return active & (disc >= 0) & (-b + root >= 0) & (-b - root <= ray.maxt * a)

    def _intersect(self, scene: mi.Scene, ray: mi.Ray3f, poses: list[tuple[Any, Any]], active: Any, k: Any, spheres: list[tuple[Any, Any]]) -> tuple[Any, Any, Any]:
        """Nearest hit over all scenes, in world space; whether it is on a mover or a
        slice; and which mover (len(movers) for none)."""
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=active)
        on_mover = mi.Bool(False)
        hit_mover = mi.UInt32(len(self.movers))
        for group in self.slices:
            for s, slice_scene in enumerate(group):
                mine = active & (k == s)
                si_s = slice_scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=mine)
                closer = mine & si_s.is_valid() & (si_s.t < si.t)
                si = dr.select(closer, si_s, si)
                on_mover |= closer
        # movers: a preliminary hit per mover (traversal only, and only for rays that meet
        # its bounding sphere at their time); the surface interaction of the nearest is
        # computed once, in its rest frame, and moved to world space
        nearest = dr.select(si.is_valid(), si.t, dr.inf)
        best = dr.zeros(mi.PreliminaryIntersection3f)
        for index, (mover, (t, q)) in enumerate(zip(self.movers, poses)):
            near = self._may_hit(spheres[index], ray, active)
            pi = mover.ray_intersect_preliminary(_to_rest(ray, t, q), coherent=False, active=near)
            closer = active & pi.is_valid() & (pi.t < nearest)
            best = dr.select(closer, pi, best)
            nearest = dr.select(closer, pi.t, nearest)
            hit_mover = dr.select(closer, mi.UInt32(index), hit_mover)
        if self.movers:
            won = active & (hit_mover < len(self.movers))
            t, q = poses[0]
            for index in range(1, len(self.movers)):
                t = dr.select(hit_mover == index, poses[index][0], t)
                q = dr.select(hit_mover == index, poses[index][1], q)
            si_m = best.compute_surface_interaction(_to_rest(ray, t, q), mi.RayFlags.All, won)
            # back to world space: p, normals and the shading frame rotate; wi is local
            si_m.p = _qrot(q, si_m.p) + t
            si_m.n = _qrot(q, si_m.n)
            si_m.sh_frame.s = _qrot(q, si_m.sh_frame.s)
            si_m.sh_frame.t = _qrot(q, si_m.sh_frame.t)
            si_m.sh_frame.n = _qrot(q, si_m.sh_frame.n)
            si_m.dp_du = _qrot(q, si_m.dp_du)
            si_m.dp_dv = _qrot(q, si_m.dp_dv)
            si = dr.select(won, si_m, si)
            on_mover |= won
        return si, on_mover, hit_mover

    def _occluded(self, scene: mi.Scene, ray: mi.Ray3f, poses: list[tuple[Any, Any]], active: Any, k: Any, spheres: list[tuple[Any, Any]]) -> Any:
        hit = scene.ray_test(ray, active)
        for group in self.slices:
            for s, slice_scene in enumerate(group):
                hit |= slice_scene.ray_test(ray, active & ~hit & (k == s))
        for index, (mover, (t, q)) in enumerate(zip(self.movers, poses)):
            near = self._may_hit(spheres[index], ray, active & ~hit)
            hit |= mover.ray_test(_to_rest(ray, t, q), near)
        return hit

    # --- lights at the path's time ---------------------------------------------------------

    def _moving_light_terms(
        self,
        scene: mi.Scene,
        sampler: mi.Sampler,
        si: Any,
        bsdf: Any,
        ctx: Any,
        poses: list[tuple[Any, Any]],
        light_poses: list[tuple[Any, Any]],
        k_slice: Any,
        active: Any,
        spheres: list[tuple[Any, Any]],
    ) -> Any:
        """Direct light at si from the moving lights and the emitters on movers, each posed
        at the path's time: the reference point goes into the light's (or mover's) rest
        frame, Mitsuba's own emitter samples a direction there, and it comes back to world
        space; the shadow ray is tested against every scene at the same time."""
        L = mi.Spectrum(0.0)
        # delta lights (point, spot, directional): one deterministic sample each, no MIS
        for index, (kind, emitter) in enumerate(self.lights):
            t, q = light_poses[index]
            it = mi.Interaction3f(si.t, si.time, si.wavelengths, _qrot(_qconj(q), si.p - t), _qrot(_qconj(q), si.n))
            ds, weight = emitter.sample_direction(it, mi.Point2f(0.5), active)
            d = _qrot(q, ds.d)
            shadow = si.spawn_ray(d) if kind == "directional" else si.spawn_ray_to(_qrot(q, ds.p) + t)
            ok = active & (ds.pdf != 0.0)
            ok &= ~self._occluded(scene, shadow, poses, ok, k_slice, spheres)
            rgb = self._vec(self._at["light_rgb"], 3, mi.UInt32(index), ok)
            value = bsdf.eval(ctx, si, si.to_local(d), ok)
            L += dr.select(ok, value * weight * mi.Spectrum(rgb.x, rgb.y, rgb.z), 0.0)
        # area emitters on movers: sampled in the mover's rest frame, MIS against BSDF sampling
        for k in self.emissive:
            t, q = poses[k]
            it = mi.Interaction3f(si.t, si.time, si.wavelengths, _qrot(_qconj(q), si.p - t), _qrot(_qconj(q), si.n))
            ds, weight = self.movers[k].sample_emitter_direction(it, sampler.next_2d(), False, active)
            d = _qrot(q, ds.d)
            ok = active & (ds.pdf != 0.0)
            ok &= ~self._occluded(scene, si.spawn_ray_to(_qrot(q, ds.p) + t), poses, ok, k_slice, spheres)
            value, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(d), ok)
            mis = dr.select(ds.delta, 1.0, _mis(ds.pdf, bsdf_pdf))
            L += dr.select(ok, mis * value * weight, 0.0)
        return L

    def _mover_emitter_pdf(self, ds: Any, ref: Any, hit_mover: Any, poses: list[tuple[Any, Any]], pdf: Any, active: Any) -> Any:
        """The solid-angle pdf with which `_moving_light_terms` would have sampled the
        emitter that a BSDF-sampled ray hit on a mover (in the mover's rest frame)."""
        for k in self.emissive:
            t, q = poses[k]
            qi = _qconj(q)
            mine = active & (hit_mover == k)
            # (built field by field: the structs' copy constructors lose fields in drjit 1.5)
            local = mi.DirectionSample3f(_qrot(qi, ds.p - t), _qrot(qi, ds.n), ds.uv, ds.time, ds.pdf, ds.delta, _qrot(qi, ds.d), ds.dist, ds.emitter)
            it = mi.Interaction3f(ref.t, ref.time, ref.wavelengths, _qrot(qi, ref.p - t), _qrot(qi, ref.n))
            pdf = dr.select(mine, self.movers[k].pdf_emitter_direction(it, local, mine), pdf)
        return pdf

    # --- AOVs -----------------------------------------------------------------------------

    def _project(self, p: Any, record: int, active: Any) -> Any:
        """Pixel coordinates of world point p seen by the camera at shutter sample `record`."""
        kind, scale, cx, cy = self._projection
        o = self._vec(self._at["camera_t"], 3, mi.UInt32(record), active)
        q = self._vec(self._at["camera_q"], 4, mi.UInt32(record), active)
        local = _qrot(_qconj(q), p - o)  # camera space: +Z forward, +Y up, +X left
        if kind == "orthographic":
            x, y = local.x * scale, local.y * scale
        else:
            z = dr.maximum(local.z, 1e-6)
            x, y = local.x / z * scale, local.y / z * scale
        return mi.Vector2f(cx - x, cy - y)

    def _motion_vector(self, si: Any, hit_mover: Any, poses: list[tuple[Any, Any]], active: Any) -> Any:
        """Screen-space motion of the first hit across the shutter, in pixels."""
        last = self.n_samples - 1
        p0, p1 = mi.Vector3f(si.p), mi.Vector3f(si.p)
        for index, (t, q) in enumerate(poses):
            mine = hit_mover == index
            rest = _qrot(_qconj(q), si.p - t)
            r = index * self.n_samples
            t0 = self._vec(self._at["mover_t"], 3, mi.UInt32(r), active)
            q0 = self._vec(self._at["mover_q"], 4, mi.UInt32(r), active)
            t1 = self._vec(self._at["mover_t"], 3, mi.UInt32(r + last), active)
            q1 = self._vec(self._at["mover_q"], 4, mi.UInt32(r + last), active)
            p0 = dr.select(mine, _qrot(q0, rest) + t0, p0)
            p1 = dr.select(mine, _qrot(q1, rest) + t1, p1)
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
        u = mi.Float(ray.time)  # shutter fraction in [0, 1]
        # camera motion inside the shutter: C(u) C(frame)^-1 applied to the primary ray
        ci, cf = self._segment(u)
        cam_t, cam_q = self._pose(self._at["camera_t"], self._at["camera_rel"], 0, ci, cf, active)
        cam_origin = self._vec(self._at["sensor_origin"], 3, mi.UInt32(0), active)
        ray = mi.Ray3f(ray)
        ray.o = _qrot(cam_q, ray.o - cam_origin) + cam_t
        ray.d = _qrot(cam_q, ray.d)

        poses = self._mover_poses(u, active)
        spheres = self._mover_spheres(poses, active)
        light_poses = self._light_poses(u, active)
        k_slice = self._slice_of(u)
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
        aov_z = mi.Float(0.0)
        aov_n = mi.Vector3f(0.0)
        aov_mv = mi.Vector2f(0.0)
        aov_albedo = mi.Color3f(0.0)
        want_aovs = len(self.aovs) > 0  # a Python bool: @dr.syntax keeps it a plain `if`

        while dr.hint(active, max_iterations=self.max_depth, label="motion_path"):
            si, on_mover, hit_mover = self._intersect(scene, ray, poses, active, k_slice, spheres)
            valid |= active & si.is_valid() & (depth == 0)
            if want_aovs:
                first = active & (depth == 0) & si.is_valid()
                if "depth" in self.aovs:
                    # camera-space depth along the view axis, with the camera at this time
                    cam_p, cam_r = self._pose(self._at["camera_t"], self._at["camera_q"], 0, ci, cf, first)
                    aov_z = dr.select(first, _qrot(_qconj(cam_r), si.p - cam_p).z, aov_z)
                if "normal" in self.aovs:
                    aov_n = dr.select(first, si.sh_frame.n, aov_n)
                if "motion" in self.aovs:
                    aov_mv = dr.select(first, self._motion_vector(si, hit_mover, poses, first), aov_mv)
                if "albedo" in self.aovs:
                    # misses count too: they see the environment (or nothing)
                    primary = active & (depth == 0)
                    aov_albedo = dr.select(primary, self._albedo(scene, si, ray, primary), aov_albedo)
            # emission reached by BSDF sampling, MIS-weighted against emitter sampling of the
            # same emitter: the static scene's, or the emissive mover's in its rest frame
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
            em_pdf = dr.select(
                ~prev_bsdf_delta & ~on_mover,
                scene.pdf_emitter_direction(prev_si, ds, ~prev_bsdf_delta & ~on_mover),
                0.0,
            )
            em_pdf = self._mover_emitter_pdf(ds, prev_si, hit_mover, poses, em_pdf, ~prev_bsdf_delta & on_mover)
            mis_bsdf = dr.select(depth == 0, 1.0, _mis(prev_bsdf_pdf, em_pdf))
            L += beta * mis_bsdf * ds.emitter.eval(si, active & (prev_bsdf_pdf > 0))

            active_next = active & si.is_valid() & (depth + 1 < self.max_depth)
            bsdf = si.bsdf(ray)

            # emitter sampling (static lights), shadow test across all scenes at time u
            active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds_em, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), False, active_em)
            active_em &= ds_em.pdf != 0.0
            shadow = si.spawn_ray_to(ds_em.p)
            occluded = self._occluded(scene, shadow, poses, active_em, k_slice, spheres)
            active_em &= ~occluded
            wo = si.to_local(ds_em.d)
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(bsdf_ctx, si, wo, active_em)
            mis_em = dr.select(ds_em.delta, 1.0, _mis(ds_em.pdf, bsdf_pdf))
            L += dr.select(active_em, beta * mis_em * bsdf_val * em_weight, 0.0)
            # moving lights and emitters on movers, each at this path's time u
            lit = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            L += beta * self._moving_light_terms(scene, sampler, si, bsdf, bsdf_ctx, poses, light_poses, k_slice, lit, spheres)

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
        aovs: list[Any] = []
        if "depth" in self.aovs:
            aovs.append(aov_z)
        if "normal" in self.aovs:
            aovs += [aov_n.x, aov_n.y, aov_n.z]
        if "motion" in self.aovs:
            aovs += [aov_mv.x, aov_mv.y]
        if "albedo" in self.aovs:
            aovs += [aov_albedo.x, aov_albedo.y, aov_albedo.z]
        return L, valid, aovs

    # --- deterministic film -------------------------------------------------------------

    # At most this many sample lanes in flight per pass: per-sample colour, film position
    # and filter weights are kept for the film, about 80 bytes a lane (~0.7 GB a pass).
    # A 1080p frame at 256 spp is 531M lanes: it runs as passes of fewer samples per pixel.
    # ($MOTION_MAX_LANES overrides it: less memory per worker, more passes.)
    max_lanes = int(os.environ.get("MOTION_MAX_LANES", 1 << 23))

    def render(
        self,
        scene: mi.Scene,
        sensor: Any = 0,
        seed: Any = 0,
        spp: int = 0,
        develop: bool = True,
        evaluate: bool = True,
    ) -> Any:
        """Render to an image whose bits do not depend on the thread count.

        Mitsuba's film splats every sample into its neighbours with atomic adds, whose
        order varies with the threads; sums of floats then differ in the last bit. Here a
        pixel's samples are consecutive lanes, so for each reconstruction-filter offset a
        `block_sum` adds one pixel's weighted samples in a fixed order, and the image
        gathers those sums offset by offset, also in a fixed order: no atomics anywhere.
        Large sample counts run as passes (see `max_lanes`), summed in pass order.
        Returns [H, W, 4 + AOV channels] (RGBA, alpha = the pixel's coverage).
        """
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        film = sensor.film()
        sampler = sensor.sampler()
        spp = int(spp) if spp else int(sampler.sample_count())
        size = film.crop_size()
        width, height = int(size[0]), int(size[1])
        # field rendering (telecine/field_render.py): only the rows offset, offset + 2, ...
        offset, step = FIELD_ROWS if FIELD_ROWS is not None else (0, 1)
        out_h = (height - offset + step - 1) // step
        n_px = width * out_h
        per_pass = max(1, min(spp, self.max_lanes // max(n_px, 1)))
        total: list[Any] | None = None
        done, index = 0, 0
        while done < spp:
            count = min(per_pass, spp - done)
            # pass 0 keeps the frame's seed; later passes derive theirs from it and the pass
            pass_seed = seed if index == 0 else mi.sample_tea_32(int(seed), index)[0]
            acc, used = self._render_pass(scene, sensor, sampler, pass_seed, count, width, height, (offset, step))
            total = acc if total is None else [t + a for t, a in zip(total, acc)]
            dr.eval(total)
            done += used
            index += 1
        assert total is not None
        weight = total[-1]
        inv = dr.select(weight > 0, dr.rcp(weight), 0.0)
        planes = [a * inv for a in total[:-1]]
        # interleave to [H, W, C]: each element written exactly once (no conflicts)
        n_ch = len(planes)
        target = dr.arange(mi.UInt32, n_px)
        flat = dr.zeros(mi.Float, n_px * n_ch)
        for c, plane in enumerate(planes):
            dr.scatter(flat, plane, target * n_ch + c)
        return mi.TensorXf(flat, shape=(out_h, width, n_ch))

    def _render_pass(self, scene: mi.Scene, sensor: Any, sampler: Any, seed: Any, spp: int, width: int, height: int, rows: tuple[int, int] = (0, 1)) -> tuple[list[Any], int]:
        """One pass of `spp` samples per pixel: per-pixel filter-weighted sums of every
        channel and of the weights (unnormalised), and the sample count actually used.
        `rows` (offset, step): only image rows offset, offset + step, ... (a field)."""
        offset, step = rows
        out_h = (height - offset + step - 1) // step
        n_px = width * out_h
        sampler.set_sample_count(spp)
        spp = int(sampler.sample_count())  # the sampler may round (multijitter)
        sampler.set_samples_per_wavefront(spp)
        sampler.seed(seed, n_px * spp)

        # ray generation in Mitsuba's order of sampler dimensions
        pixel = dr.arange(mi.UInt32, n_px * spp) // spp
        px = mi.Vector2f(mi.Float(pixel % width), mi.Float(offset + step * (pixel // width)))
        film_pos = px + sampler.next_2d()
        time = sensor.shutter_open() + sampler.next_1d() * sensor.shutter_open_time()
        aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
        ray, ray_weight = sensor.sample_ray_differential(time, 0.0, film_pos / mi.Vector2f(width, height), aperture)
        L, valid, aovs = self.sample(scene, sampler, ray, None, True)
        L = L * ray_weight
        channels = [L[0], L[1], L[2], dr.select(valid, 1.0, 0.0), *aovs]
        dr.eval(channels, film_pos)

        # reconstruction, one row of filter offsets oy at a time: every source pixel sums,
        # over its own samples in order, the filter-weighted channels it sends to each of
        # the pixels (ox, oy) away (`_row_sums`: one kernel); then every target pixel
        # gathers those sums from its neighbours, offset by offset in a fixed order
        rfilter = sensor.film().rfilter()
        reach = max(0, int(np.ceil(rfilter.radius() - 0.5)))
        target = dr.arange(mi.UInt32, n_px)
        tx, ty = mi.Int32(target % width), mi.Int32(target // width)
        acc = [mi.Float(dr.zeros(mi.Float, n_px)) for _ in range(len(channels) + 1)]
        for oy in range(-reach, reach + 1):
            if oy % step:
                continue  # a row of the other field: not rendered
            sums = self._row_sums(rfilter, channels, film_pos, spp, width, n_px, oy, reach, (offset, step))
            dr.eval(sums)
            for ox in range(-reach, reach + 1):
                sx, sy = tx - ox, ty - oy // step  # the source pixel whose samples land here
                ok = (sx >= 0) & (sx < width) & (sy >= 0) & (sy < out_h)
                src = mi.UInt32(dr.select(ok, sy * width + sx, 0))
                acc = [a + dr.gather(mi.Float, v, src, ok) for a, v in zip(acc, sums[ox + reach])]
            dr.eval(acc)
        return acc, spp

    @staticmethod
    def _row_sums(rfilter: Any, channels: list[Any], film_pos: Any, spp: int, width: int, n_px: int, oy: int, reach: int, rows: tuple[int, int] = (0, 1)) -> list[list[Any]]:
        """For every source pixel (one lane each) and each x offset ox in [-reach, reach]:
        the sums over the pixel's spp samples, in sample order, of channel * w and of w,
        where w = f(x) f(y) is the separable filter's weight of the sample for the pixel
        (ox, oy) away. Returns [2 reach + 1][channels + 1] arrays of n_px."""
        source = dr.arange(mi.UInt32, n_px)
        sx, sy = mi.Float(source % width), mi.Float(rows[0] + rows[1] * (source // width))  # frame rows (a field: every other)
        widths = 2 * reach + 1
        zero = [mi.Float(dr.zeros(mi.Float, n_px)) for _ in range(widths * (len(channels) + 1))]

        def body(s: Any, *acc: Any) -> tuple[Any, ...]:
            index = source * spp + s
            fx = dr.gather(mi.Float, film_pos.x, index)
            fy = dr.gather(mi.Float, film_pos.y, index)
            values = [dr.gather(mi.Float, c, index) for c in channels]
            wy = rfilter.eval(sy + (oy + 0.5) - fy)  # the target pixel's centre minus the sample
            out = list(acc)
            k = 0
            for ox in range(-reach, reach + 1):
                w = rfilter.eval(sx + (ox + 0.5) - fx) * wy
                for v in values:
                    out[k] = out[k] + v * w
                    k += 1
                out[k] = out[k] + w
                k += 1
            return (s + 1, *out)

        state = dr.while_loop((mi.UInt32(0), *zero), lambda s, *acc: s < spp, body, label="film_row")
        flat = list(state[1:])
        per = len(channels) + 1
        return [flat[i * per : (i + 1) * per] for i in range(widths)]

    def aov_names(self) -> list[str]:
        names: list[str] = []
        if "depth" in self.aovs:
            names.append("Z")
        if "normal" in self.aovs:
            names += ["N.X", "N.Y", "N.Z"]
        if "motion" in self.aovs:
            names += ["motion.X", "motion.Y"]
        if "albedo" in self.aovs:
            names += ["albedo.R", "albedo.G", "albedo.B"]
        return names

    def to_string(self) -> str:
        return f"MotionPathIntegrator[max_depth={self.max_depth}, movers={len(self.movers)}]"


def _spheres(movers: Sequence[mi.Scene]) -> np.ndarray:
    """Each scene's bounding sphere (centre, radius) from its bounding box, padded a little
    so that a grazing ray is never culled by rounding."""
    out = np.zeros((len(movers), 4))
    for k, mover in enumerate(movers):
        box = mover.bbox()
        lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
        out[k, :3] = (lo + hi) / 2
        out[k, 3] = np.linalg.norm(hi - lo) / 2 * (1 + 1e-4) + 1e-5
    return out

# (row offset, row step) while a field is rendered (telecine/field_render.py sets it);
# None: every row
FIELD_ROWS: tuple[int, int] | None = None

_registered = False


def register() -> None:
    """Make `{"type": "motion_path"}` available to mi.load_dict (once per process)."""
    global _registered
    if not _registered:
        mi.register_integrator("motion_path", lambda props: MotionPathIntegrator(props))
        _registered = True
