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

from typing import Any, NamedTuple, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import FrameDataError
from ..motion.pose import SLERP_LINEAR_BELOW, quat_rotate

# The blocks of the per-frame data array, in order (see `FrameData.set`):
#   mover_t [M, N, 3], mover_q [M, N, 4]   movers' world_from_object across the shutter
#   camera_t [N, 3], camera_rel [N, 4]     camera translation, rotation C(u) C(frame)^-1
#   sensor_origin [3]                      the sensor's position at the frame time
#   camera_q [N, 4]                        camera rotation across the shutter
#   light_t [L, N, 3], light_q [L, N, 4]   moving lights' world_from_light across the shutter
#   light_rgb [L, 3]                       moving lights' colours at the frame time
#   mover_sphere [M, 4]                    movers' rest-frame bounding spheres (centre, radius)
#   mover_swept [M, 4]                     movers' world-space spheres across the shutter
FRAME_BLOCKS = ("mover_t", "mover_q", "camera_t", "camera_rel", "sensor_origin", "camera_q", "light_t", "light_q", "light_rgb", "mover_sphere", "mover_swept")


def qrot(q: Any, v: Any) -> Any:
    """Rotate vector v by unit quaternion q = (w, x, y, z) stored as mi.Vector4f."""
    u = mi.Vector3f(q.y, q.z, q.w)
    w = q.x
    t = 2 * dr.cross(u, v)
    return v + w * t + dr.cross(u, t)


def qconj(q: Any) -> Any:
    """The conjugate (the inverse rotation) of unit quaternion q = (w, x, y, z)."""
    return mi.Vector4f(q.x, -q.y, -q.z, -q.w)


def slerp(q0: Any, q1: Any, f: Any) -> Any:
    """Shortest-arc spherical interpolation of unit quaternions (w, x, y, z)."""
    d = dr.dot(q0, q1)
    q1 = dr.select(d < 0, -q1, q1)
    d = dr.abs(d)
    theta = dr.acos(dr.minimum(d, 1.0))
    s = dr.sin(theta)
    small = s < SLERP_LINEAR_BELOW["float32"]
    w0 = dr.select(small, 1 - f, dr.sin((1 - f) * theta) / s)
    w1 = dr.select(small, f, dr.sin(f * theta) / s)
    return dr.normalize(w0 * q0 + w1 * q1)


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


def bounding_spheres(movers: Sequence[mi.Scene]) -> np.ndarray:
    """Each mover's bounding sphere in its rest frame (centre, radius): about the centre of
    its box, as tight as its shapes allow: a mesh's farthest vertex, a sphere's own radius,
    otherwise the farthest corner of the shape's box. A sphere is culled by a sphere 1.73x
    smaller across than its box's, so rays near it, and the branches they take in
    world.py, are a third as many. Padded a little so a grazing ray is never culled by
    rounding."""
    out = np.zeros((len(movers), 4))
    for k, mover in enumerate(movers):
        box = mover.bbox()
        lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
        centre = (lo + hi) / 2
        reach = 0.0
        for shape in mover.shapes():
            reach = max(reach, _shape_reach(shape, centre))
        out[k, :3] = centre
        out[k, 3] = reach * (1 + 1e-4) + 1e-5
    return out


def _shape_reach(shape: Any, centre: np.ndarray) -> float:
    """The farthest any point of `shape` lies from `centre` (an upper bound)."""
    box = shape.bbox()
    lo, hi = np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()
    if shape.is_mesh():
        vertices = np.array(shape.vertex_positions_buffer(), dtype=float).reshape(-1, 3)
        if len(vertices):
            return float(np.sqrt(((vertices - centre) ** 2).sum(axis=1).max()))
    elif shape.shape_type() == int(mi.ShapeType.Sphere):
        return float(np.linalg.norm((lo + hi) / 2 - centre) + (hi[0] - lo[0]) / 2)
    return float(np.linalg.norm(np.maximum(np.abs(lo - centre), np.abs(hi - centre))))


def swept_spheres(t: np.ndarray, q: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Each mover's world-space sphere [M, 4] (centre, radius) that holds it at every time
    of the shutter, from its N baked samples t [M, N, 3], q [M, N, 4] and its rest-frame
    bounding sphere rest [M, 4] (`bounding_spheres`).

    Between samples j and j + 1 the rest centre c lies at lerp(t) + slerp(q) c: inside the
    parallelogram of the four points t_a + R(q_b) c (a, b in {j, j + 1}), but for the arc
    that the rotation bows out of its chord, by at most |c| (1 - cos(theta / 2)) =
    |c| (1 - |q_j . q_j+1|). The sphere holds all those corners, that bow and the rest
    radius, padded for float32 rounding in the kernel (positions far from the origin round
    to about 6e-8 of their distance)."""
    m = len(rest)
    out = np.zeros((m, 4))
    if m == 0:
        return out
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    c = np.broadcast_to(np.asarray(rest, dtype=float)[:, None, :3], t.shape)
    rc = quat_rotate(q, c)
    corners = np.concatenate([t + rc, t[:, :-1] + rc[:, 1:], t[:, 1:] + rc[:, :-1]], axis=1)
    centre = (corners.min(axis=1) + corners.max(axis=1)) / 2
    reach = np.sqrt(((corners - centre[:, None]) ** 2).sum(axis=2)).max(axis=1)
    dots = np.abs((q[:, :-1] * q[:, 1:]).sum(axis=2)) if q.shape[1] > 1 else np.ones((m, 1))
    bow = np.linalg.norm(rest[:, :3], axis=1) * (1.0 - np.minimum(dots, 1.0)).max(axis=1)
    radius = reach + bow + rest[:, 3]
    out[:, :3] = centre
    out[:, 3] = radius * (1 + 1e-4) + 1e-6 * np.abs(centre).max(axis=1) + 1e-5
    return out


class MoverTracks:
    """The rigid movers at a path's time u, read from the frame data.

    A mover's pose is computed either once per path, before the first ray (`eager`), or
    on demand where a ray needs it. A ray first meets each mover's swept sphere (`swept`:
    one value for all lanes, from `swept_spheres`); only lanes past it need the mover's
    pose at their own time (`pose`) and its posed bounding sphere (`posed_sphere`),
    exactly as tight as before. On demand, a mover few rays come near costs next to
    nothing, where its eager pose would cost every path a slerp and keep 7 floats a lane
    live across the whole path loop (16 movers: 30% of the frame); but a mover that many
    rays meet at every bounce is posed again at each, and there the eager pose is cheaper
    (a close-up spinning top: about 10%). `eager_movers` decides per mover, once per job.
    The pixels are the same bits either way."""

    def __init__(self, data: FrameData, count: int, u: Any, active: Any, eager: Sequence[bool] = ()) -> None:
        self.data = data
        self.count = count
        self.active = active
        self.segment = data.segment(u)
        self._poses: dict[int, KernelPose] = {k: self._pose(k) for k in range(count) if k < len(eager) and eager[k]}

    def __len__(self) -> int:
        return self.count

    def _pose(self, index: Any) -> KernelPose:
        i, f = self.segment
        return self.data.pose("mover_t", "mover_q", index * self.data.n_samples, i, f, self.active)

    def pose(self, index: Any) -> KernelPose:
        """Mover `index` (an int, or a mi.UInt32 per lane below the count) at the path's time."""
        if isinstance(index, int) and index in self._poses:
            return self._poses[index]
        return self._pose(index)

    def swept(self, index: int) -> tuple[Any, Any]:
        """Mover `index`'s sphere across the whole shutter (world centre, squared radius)."""
        s = self.data.vec("mover_swept", 4, mi.UInt32(index), self.active)
        return mi.Vector3f(s.x, s.y, s.z), dr.square(s.w)

    def posed_sphere(self, index: int, pose: KernelPose) -> tuple[Any, Any]:
        """Mover `index`'s bounding sphere at the path's time (world centre, squared radius)."""
        s = self.data.vec("mover_sphere", 4, mi.UInt32(index), self.active)
        return qrot(pose.q, mi.Vector3f(s.x, s.y, s.z)) + pose.t, dr.square(s.w)


def eager_movers(swept: np.ndarray, eye: np.ndarray, projection: tuple[str, float], pixels: int, share: float = 0.02) -> list[bool]:
    """Which movers `MoverTracks` poses once per path: those whose swept sphere [M, 4]
    covers more than `share` of the image seen from `eye` (camera rays that meet it are
    likely to meet it again at later bounces); the others on demand. `projection`: the
    kind (perspective, orthographic) and scale, pixels per unit at distance 1 (perspective)
    or per metre (orthographic); `pixels`: the image's pixel count."""
    kind, scale = projection
    out = []
    for centre, radius in zip(swept[:, :3], swept[:, 3]):
        distance = float(np.linalg.norm(centre - eye))
        if kind == "orthographic":
            rho = scale * radius
        elif distance <= radius:
            out.append(True)  # the camera is inside it
            continue
        else:
            rho = scale * radius / np.sqrt(distance**2 - radius**2)
        out.append(bool(np.pi * rho**2 > share * pixels))
    return out


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
