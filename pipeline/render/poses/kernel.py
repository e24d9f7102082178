"""Moving-object poses at a ray's time, for the `motion_path` integrator (drjit side).

Everything that moves inside a frame's shutter (rigid movers, the camera, moving lights) is
posed per sample from baked samples across the shutter. They all come to the kernels in
ONE opaque float array per frame (`FrameData`): its blocks (`FRAME_BLOCKS`) sit at named
offsets, fixed for a job, so a new frame replays the compiled kernels instead of
compiling new ones. At shutter fraction u a pose is interpolated between the two samples
around u: translation linearly, rotation by shortest-arc slerp (never a matrix lerp).

A `KernelPose` (world_from_object as translation t and unit quaternion q) maps rays, points,
vectors and interactions between world space and the body's rest frame, the one place
where the inverse rigid transform is written (docs/rendering.md, "Time per sample").
"""

from __future__ import annotations

from typing import Any, NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from ...errors import FrameDataError
from ...motion.pose import SLERP_LINEAR_BELOW, ArrayOps, slerp_with

# The blocks of the per-frame data array, in order (see `FrameData.set`):
#   mover_t [M, N, 3], mover_q [M, N, 4]   movers' world_from_object across the shutter
#   mover_template [M, 2]                  each mover's first template and their count S (`Movers.template_of`)
#   camera_t [N, 3], camera_rel [N, 4]     camera translation, rotation C(u) C(frame)^-1
#   sensor_origin [3]                      the sensor's position at the frame time
#   camera_q [N, 4]                        camera rotation across the shutter
#   light_t [L, N, 3], light_q [L, N, 4]   moving lights' world_from_light across the shutter
#   light_rgb [L, 3]                       moving lights' colours at the frame time
#   template_offset [T, 3]                 each template's offset in the atlas (render/kernel/atlas.py)
#   template_box [T, 2, 3]                 each template's padded box in the atlas
#   template_sphere [T, 4]                 each template's rest-frame bounding sphere
#   particle_p [C, N, 3]                   particles' centres across the shutter
#   particle_alive [C, N]                  1 where a particle is alive at a sample, else 0
#   particle_template [C]                  the template (its system's holder) of each particle
#   reach [1]                              how far behind a ray the broadphase walk starts
#   proxy_box [2, 3]                       the box holding every live proxy (world space)
#   regions [2]                            the shutter's parts B and their regions' spacing (render/kernel/broadphase.py)
FRAME_BLOCKS = (
    "mover_t", "mover_q", "mover_template", "camera_t", "camera_rel", "sensor_origin", "camera_q", "light_t", "light_q", "light_rgb",
    "template_offset", "template_box", "template_sphere", "particle_p", "particle_alive", "particle_template", "reach",
    "proxy_box", "regions",
)


def qrot(q: Any, v: Any) -> Any:
    """Rotate vector v by unit quaternion q = (w, x, y, z) stored as mi.Vector4f."""
    u = mi.Vector3f(q.y, q.z, q.w)
    w = q.x
    t = 2 * dr.cross(u, v)
    return v + w * t + dr.cross(u, t)


def qconj(q: Any) -> Any:
    """The conjugate (the inverse rotation) of unit quaternion q = (w, x, y, z)."""
    return mi.Vector4f(q.x, -q.y, -q.z, -q.w)


# motion.pose's one slerp, on drjit's operations at float32's threshold
DRJIT = ArrayOps(dr.dot, dr.select, dr.abs, dr.acos, dr.sin, dr.minimum, dr.normalize, SLERP_LINEAR_BELOW["float32"])


def slerp(q0: Any, q1: Any, f: Any) -> Any:
    """Shortest-arc spherical interpolation of unit quaternions (w, x, y, z) as
    mi.Vector4f: motion.pose's `slerp_with`, the one slerp, on drjit (float32)."""
    return slerp_with(DRJIT, q0, q1, f)


class KernelPose(NamedTuple):
    """A rigid world_from_object transform inside the render kernel (drjit values; the motion
    stage's numpy `motion.pose.Pose` is the CPU side): translation t (mi.Vector3f) and unit
    quaternion q (mi.Vector4f). Rigid maps keep lengths, so ray parameters and local BSDF directions are
    the same in both frames."""

    t: Any
    q: Any

    def point_to_rest(self, p: Any) -> Any:
        """object_from_world applied to a point."""
        return qrot(qconj(self.q), p - self.t)

    def vector_to_rest(self, v: Any) -> Any:
        """object_from_world applied to a direction or normal."""
        return qrot(qconj(self.q), v)

    def point_to_world(self, p: Any) -> Any:
        """world_from_object applied to a point."""
        return qrot(self.q, p) + self.t

    def vector_to_world(self, v: Any) -> Any:
        """world_from_object applied to a direction or normal."""
        return qrot(self.q, v)

    def ray_to_rest(self, ray: Any) -> Any:
        """The ray in the body's rest frame."""
        qi = qconj(self.q)
        local = mi.Ray3f(ray)
        local.o = qrot(qi, ray.o - self.t)
        local.d = qrot(qi, ray.d)
        return local

    def interaction_to_rest(self, it: Any) -> Any:
        """A reference point (position and normal) in the body's rest frame, for emitter
        sampling and pdf queries there."""
        return mi.Interaction3f(it.t, it.time, it.wavelengths, self.point_to_rest(it.p), self.vector_to_rest(it.n))

    def direction_sample_to_rest(self, ds: Any) -> Any:
        """A world-space direction sample in the body's rest frame (built field by field:
        the structs' copy constructors lose fields in drjit 1.5)."""
        qi = qconj(self.q)
        return mi.DirectionSample3f(qrot(qi, ds.p - self.t), qrot(qi, ds.n), ds.uv, ds.time, ds.pdf, ds.delta, qrot(qi, ds.d), ds.dist, ds.emitter)

    def surface_to_world(self, si: Any) -> Any:
        """A rest-frame surface interaction moved to world space: p, normals, the shading
        frame and the surface derivatives rotate; wi is local and stays as it is."""
        si.p = qrot(self.q, si.p) + self.t
        si.n = qrot(self.q, si.n)
        si.sh_frame.s = qrot(self.q, si.sh_frame.s)
        si.sh_frame.t = qrot(self.q, si.sh_frame.t)
        si.sh_frame.n = qrot(self.q, si.sh_frame.n)
        si.dp_du = qrot(self.q, si.dp_du)
        si.dp_dv = qrot(self.q, si.dp_dv)
        return si


class FrameData:
    """The per-frame poses of one job in ONE opaque array, read by name.

    With several fresh arrays per frame, drjit recycles variable indices from two frames
    back, their relative order flips and the kernel's input order with it, which
    alternates between two kernel variants; one array keeps one kernel."""

    def __init__(self) -> None:
        self.array = mi.Float(0.0)
        self.at: dict[str, int] = dict.fromkeys(FRAME_BLOCKS, 0)  # block name -> element offset
        self.n_samples = 2  # baked samples across the shutter (N)

    def set(self, blocks: dict[str, tuple[Any, tuple[int, ...]]]) -> None:
        """Write one frame: `blocks` maps every name of FRAME_BLOCKS to (values, the shape
        they must have). A wrong shape is a `FrameDataError`."""
        flat = []
        for name in FRAME_BLOCKS:
            value, shape = blocks[name]
            value = np.asarray(value, dtype=np.float32)
            if value.shape != shape:
                raise FrameDataError(f"frame data {name!r} has shape {value.shape}, expected {shape}")
            flat.append(value.ravel())
        # element offsets of each block; the gathers below index in units of 3 or 4 floats
        offsets = np.cumsum([0, *(len(a) for a in flat[:-1])])
        self.at = {name: int(o) for name, o in zip(FRAME_BLOCKS, offsets)}
        self.array = mi.Float(np.concatenate(flat))
        # opaque: new values each frame must not become new literals in the kernel
        dr.make_opaque(self.array)

    def segment(self, u: Any) -> tuple[Any, Any]:
        """The shutter segment [i, i + 1] of the N samples holding fraction u, and the
        position f in [0, 1] inside it."""
        x = dr.clip(u, 0.0, 1.0) * (self.n_samples - 1)
        i = dr.minimum(mi.UInt32(dr.floor(x)), self.n_samples - 2)
        return i, x - mi.Float(i)

    def vec(self, block: str, width: int, j: Any, active: Any) -> Any:
        """Element j of the `width`-float records of `block` (mi.Vector3f or Vector4f)."""
        base = self.at[block] + j * width
        comps = [dr.gather(mi.Float, self.array, base + c, active) for c in range(width)]
        return mi.Vector3f(*comps) if width == 3 else mi.Vector4f(*comps)

    def scalar(self, block: str, j: Any, active: Any) -> Any:
        """Element j of the one-float records of `block` (mi.Float)."""
        return dr.gather(mi.Float, self.array, self.at[block] + j, active)

    def pose(self, t_block: str, q_block: str, record: int, i: Any, f: Any, active: Any) -> KernelPose:
        """The pose of the track starting at sample `record` of the blocks, at position f
        of segment i: translation lerped, rotation slerped."""
        j = record + i
        t0 = self.vec(t_block, 3, j, active)
        t1 = self.vec(t_block, 3, j + 1, active)
        q0 = self.vec(q_block, 4, j, active)
        q1 = self.vec(q_block, 4, j + 1, active)
        return KernelPose(dr.lerp(t0, t1, f), slerp(q0, q1, f))

    def sample_pose(self, t_block: str, q_block: str, record: Any, active: Any) -> KernelPose:
        """The baked sample `record` (an int, or a mi.UInt32 per lane) of the blocks, as it
        is (no interpolation)."""
        return KernelPose(self.vec(t_block, 3, mi.UInt32(record), active), self.vec(q_block, 4, mi.UInt32(record), active))

    def poses(self, t_block: str, q_block: str, count: int, u: Any, active: Any) -> list[KernelPose]:
        """The poses at shutter fraction u of `count` tracks of N samples each."""
        i, f = self.segment(u)
        return [self.pose(t_block, q_block, k * self.n_samples, i, f, active) for k in range(count)]


# --- bounding spheres: rays that miss a mover never pay for its traversal -----------------


class Movers:
    """Everything the broadphase holds, at a path's time u, read from the frame data:
    proxy k < `rigid` is rigid mover k (its pose lerped and slerped between the baked
    samples around u); proxy k >= `rigid` is particle k - rigid (its centre lerped between
    the samples around u, no rotation). Each proxy draws a template of the atlas
    (render/kernel/atlas.py): a mover its own, a particle its system's holder sphere. Poses are
    computed where a ray needs them, per lane, by index: one code path for any count."""

    def __init__(self, data: FrameData, rigid: int, particles: int, u: Any, active: Any) -> None:
        self.data = data
        self.rigid = rigid
        self.particles = particles
        self.active = active
        self.u = u  # the path's shutter fraction
        self.segment = data.segment(u)

    def __len__(self) -> int:
        return self.rigid

    @property
    def total(self) -> int:
        """Rigid movers and particles: the broadphase's proxies."""
        return self.rigid + self.particles

    def pose(self, index: Any) -> KernelPose:
        """Rigid mover `index` (an int, or a mi.UInt32 per lane below the count) at the path's time."""
        i, f = self.segment
        return self.data.pose("mover_t", "mover_q", index * self.data.n_samples, i, f, self.active)

    def particle(self, j: Any, active: Any) -> tuple[Any, Any]:
        """Particle j's centre at the path's time and whether it is alive then: lerped
        between the samples around u where it is alive at both, else the nearer one's
        (a particle born or dying inside the segment)."""
        i, f = self.segment
        n = self.data.n_samples
        a0 = self.data.scalar("particle_alive", j * n + i, active) > 0.5
        a1 = self.data.scalar("particle_alive", j * n + i + 1, active) > 0.5
        c0 = self.data.vec("particle_p", 3, j * n + i, active)
        c1 = self.data.vec("particle_p", 3, j * n + i + 1, active)
        both = a0 & a1
        centre = dr.select(both, dr.lerp(c0, c1, f), dr.select(a0, c0, c1))
        alive = both | dr.select(f < 0.5, a0, a1)
        return centre, alive

    def template_of(self, k: Any, active: Any) -> Any:
        """The template rigid mover k draws at the path's time: its own (S = 1), or for a
        deforming mesh one of its S residual templates (render/translate/deforming.py), the two around
        u chosen with probabilities by their distance to it, by a hash of u (the same for
        every query of one path: its scene at its time is one scene)."""
        first = mi.UInt32(self.data.scalar("mover_template", k * 2, active))
        count = self.data.scalar("mover_template", k * 2 + 1, active)
        x = dr.clip(self.u, 0.0, 1.0) * dr.maximum(count - 1.0, 0.0)
        below = dr.floor(x)
        dither = mi.sample_tea_float32(dr.reinterpret_array(mi.UInt32, mi.Float(self.u)), mi.UInt32(0x9E3779B9), 4)
        pick = dr.minimum(below + dr.select(dither < x - below, 1.0, 0.0), dr.maximum(count - 1.0, 0.0))
        return first + mi.UInt32(pick)

    def proxy(self, k: Any, active: Any) -> tuple[KernelPose, Any, Any]:
        """Proxy k's pose at the path's time (world_from_rest), its template and whether
        it exists then (a particle alive)."""
        rigid = k < self.rigid
        if self.particles == 0:
            return self.pose(dr.select(rigid, k, 0)), self.template_of(k, active), mi.Bool(active)
        if self.rigid == 0:
            j = k - self.rigid
            centre, alive = self.particle(j, active)
            template = mi.UInt32(self.data.scalar("particle_template", j, active))
            return KernelPose(centre, mi.Vector4f(1.0, 0.0, 0.0, 0.0)), template, active & alive
        mover = self.pose(dr.select(rigid, k, 0))
        j = dr.select(rigid, 0, k - self.rigid)
        centre, alive = self.particle(j, active & ~rigid)
        template = dr.select(rigid, self.template_of(dr.select(rigid, k, 0), active & rigid), mi.UInt32(self.data.scalar("particle_template", j, active & ~rigid)))
        pose = KernelPose(dr.select(rigid, mover.t, centre), dr.select(rigid, mover.q, mi.Vector4f(1.0, 0.0, 0.0, 0.0)))
        return pose, template, active & (rigid | alive)

    def proxy_at_sample(self, k: Any, record: int, active: Any) -> KernelPose:
        """Proxy k's pose at baked sample `record` (0 .. N-1), for motion vectors."""
        n = self.data.n_samples
        rigid = k < self.rigid
        mover = self.data.sample_pose("mover_t", "mover_q", dr.select(rigid, k, 0) * n + record, active & rigid) if self.rigid else None
        if self.particles == 0:
            return mover  # type: ignore[return-value]
        j = dr.select(rigid, 0, k - self.rigid)
        centre = self.data.vec("particle_p", 3, j * n + record, active & ~rigid)
        still = KernelPose(centre, mi.Vector4f(1.0, 0.0, 0.0, 0.0))
        if mover is None:
            return still
        return KernelPose(dr.select(rigid, mover.t, still.t), dr.select(rigid, mover.q, still.q))

    def template_sphere(self, template: Any, pose: KernelPose, active: Any) -> tuple[Any, Any]:
        """A template's bounding sphere posed at the path's time (world centre, squared radius)."""
        s = self.data.vec("template_sphere", 4, template, active)
        return pose.point_to_world(mi.Vector3f(s.x, s.y, s.z)), dr.square(s.w)

    def template_box(self, template: Any, active: Any) -> tuple[Any, Any, Any]:
        """A template's atlas offset and padded box (min, max)."""
        offset = self.data.vec("template_offset", 3, template, active)
        lo = self.data.vec("template_box", 3, template * 2, active)
        hi = self.data.vec("template_box", 3, template * 2 + 1, active)
        return offset, lo, hi


def may_hit(sphere: tuple[Any, Any], ray: Any, active: Any, maxt: Any = None) -> Any:
    """Whether the ray's segment [0, maxt] (default: the ray's own maxt) meets a sphere
    given as (world centre, squared radius): `MoverTracks.swept` or `.posed_sphere`."""
    centre, r2 = sphere
    maxt = ray.maxt if maxt is None else maxt
    oc = ray.o - centre
    a = dr.squared_norm(ray.d)
    b = dr.dot(oc, ray.d)
    disc = dr.square(b) - a * (dr.squared_norm(oc) - r2)
    root = dr.safe_sqrt(disc)
    # the segment [0, maxt] meets the sphere: roots (-b -+ root) / a straddle some of it
    return active & (disc >= 0) & (-b + root >= 0) & (-b - root <= maxt * a)
