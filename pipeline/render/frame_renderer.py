"""The "first frame" layer: a worker builds the Mitsuba scene once and keeps it for every
frame it renders; a new frame changes only what moved.

What is paid once per (scene, settings) in a worker process (the cold frame): loading and
converting assets (through the shared disk cache), building the static set and its BVH,
the movers' rest-frame scenes, and compiling the kernels (or loading them from drjit's
disk cache). What a warm frame pays: the camera's sensor pose (a parameter update that
rebuilds no BVH), moving lights' parameters, the movers' per-sample poses (opaque arrays
read by the integrator, no BVH rebuild, no recompilation), and the render itself.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..bake import BakedFrame
from ..motion.pose import quat_mul, quat_rotate, slerp
from ..scene.loader import LoadedScene
from ..scene.schema import Empty, Particles
from .build import (
    LIGHT_CHANNEL,
    light_dict,
    material_dict,
    object_shapes,
    sensor_dict,
    trs_matrix,
    unit_light_dict,
)


@dataclass(frozen=True)
class StackedFrame:
    """The renderer's own view of one `BakedFrame`, built by `stack_frame` alone: every
    track stacked as [frame time, N shutter samples], row 0 at the frame time and rows
    1..N across the shutter (`samples` = N)."""

    frame: int
    time: float
    shutter: tuple[float, float]
    samples: int
    objects: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]  # name -> (t [1+N,3], q [1+N,4], s [1+N,3])
    camera: tuple[np.ndarray, np.ndarray]  # (t [1+N,3], q [1+N,4])
    fov: np.ndarray  # [1+N]
    lights: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    light_scalars: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    vertices: dict[str, np.ndarray] = field(default_factory=dict)  # deforming meshes [1+N, V, 3], object space
    ortho_width: np.ndarray | None = None  # [1+N], orthographic cameras
    particles: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # (positions [1+N, n, 3], alive [1+N, n])


def stack_frame(frame: BakedFrame) -> StackedFrame:
    """`frame.at_frame` followed by `frame.across_shutter`, track by track."""
    at, across = frame.at_frame, frame.across_shutter

    def pose(p: Any, q: Any) -> tuple[np.ndarray, ...]:
        return tuple(np.concatenate([x, y]) for x, y in zip(p, q))

    fov = np.concatenate([at.camera_scalars["fov"], across.camera_scalars["fov"]])
    ortho = np.concatenate([at.camera_scalars["ortho_width"], across.camera_scalars["ortho_width"]]) if "ortho_width" in at.camera_scalars else None
    return StackedFrame(
        frame=frame.frame,
        time=float(frame.time),
        shutter=(float(frame.shutter[0]), float(frame.shutter[1])),
        samples=len(across.times),
        objects={n: pose(p, across.objects[n]) for n, p in at.objects.items()},  # type: ignore[misc]
        camera=pose(at.camera, across.camera)[:2],  # type: ignore[arg-type]
        fov=np.asarray(fov, dtype=float),
        ortho_width=None if ortho is None else np.asarray(ortho, dtype=float),
        lights={n: pose(p, across.lights[n]) for n, p in at.lights.items()},  # type: ignore[misc]
        light_scalars={n: {c: np.concatenate([v, across.light_scalars[n][c]]) for c, v in d.items()} for n, d in at.light_scalars.items()},
        vertices={n: np.concatenate([v, across.vertices[n]]) for n, v in at.vertices.items()},
        particles={
            n: (np.concatenate([p.positions, across.particles[n].positions]), np.concatenate([p.alive, across.particles[n].alive]))
            for n, p in at.particles.items()
        },
    )


@dataclass
class FrameStats:
    frame: int
    cold: bool
    setup_s: float
    render_s: float
    kernels_compiled: int
    kernels_reused: int
    asset_cache_hits: int
    scene_reused: bool
    updated_params: tuple[str, ...] = ()  # scene parameters changed for this frame


def frame_seed(seed: int, frame: int, policy: str) -> int:
    """Deterministic per-frame seed: the same for every worker that renders the frame."""
    if policy == "fixed":
        return int(seed)
    digest = hashlib.sha256(f"{seed}:{frame}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def is_static(loaded: LoadedScene, name: str) -> bool:
    """An object is static iff neither it nor any ancestor moves."""
    by_name = {o.name: o for o in loaded.scene.objects}
    node = by_name.get(name)
    while node is not None:
        if node.motion.type != "static":
            return False
        node = by_name.get(node.parent) if node.parent else None
    return True




def resample(t: np.ndarray, q: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose at shutter fraction u from N samples spanning the shutter (lerp + slerp)."""
    n = len(t)
    x = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(np.floor(x)), n - 2)
    f = x - i
    return (1 - f) * t[i] + f * t[i + 1], slerp(q[i], q[i + 1], f)


class FrameRenderer:
    """Renders the frames of one scene in one worker process, keeping everything it can."""

    def __init__(self, loaded: LoadedScene, spp: int | None = None) -> None:
        import drjit as dr
        import mitsuba as mi

        from .integrator import register

        register()
        self.loaded = loaded
        self.settings = loaded.scene.render
        self.spp = int(spp or self.settings.spp)
        # `integrator: direct` is direct lighting only: paths of one bounce
        self.max_depth = 2 if self.settings.integrator == "direct" else self.settings.max_depth
        self._mi, self._dr = mi, dr
        self._scene: Any = None
        self._params: Any = None
        self._frames_done = 0
        # The motion_path integrator is vectorised drjit code: LLVM or CUDA variants only.
        # The scalar fallback renders with Mitsuba's own `path`, movers placed per sub-frame.
        self.vectorized = not mi.variant().startswith("scalar")
        objects = loaded.scene.objects
        # non-rigid geometry: particle systems and deforming meshes render as time slices
        self.slice_names = [o.name for o in objects if o.visible and (isinstance(o, Particles) or getattr(o, "deform", None) is not None)]
        self.static_names = [o.name for o in objects if is_static(loaded, o.name) and o.name not in self.slice_names]
        self.mover_names = [
            o.name
            for o in objects
            if o.name not in self.static_names and o.name not in self.slice_names and not isinstance(o, (Empty, Particles)) and o.visible
        ]
        # lights whose pose can change (their own motion or a moving parent)
        animated = [
            (i, light)
            for i, light in enumerate(loaded.scene.lights)
            if light.motion.type != "static" or (light.parent is not None and not is_static(loaded, light.parent))
        ]
        # moving point, spot and directional lights are posed per path by the integrator
        # (at the sample's time); animated environment lights are updated per frame
        self.moving_lights = [(i, light) for i, light in animated if light.type in ("point", "spot", "directional")]
        self._animated_lights = [(i, light) for i, light in animated if light.type not in ("point", "spot", "directional")]
        self._groups: list[Any] = []
        self.last_aovs: dict[str, np.ndarray] = {}
        dr.set_flag(dr.JitFlag.KernelHistory, True)

    # --- build (cold) -----------------------------------------------------------------

    def _build(self, fi: StackedFrame) -> None:
        mi = self._mi
        scene = self.loaded.scene
        materials = {m.name: material_dict(m, self.loaded) for m in scene.materials}
        d: dict[str, Any] = {"type": "scene"}
        from .denoise import integrator_aovs

        aovs = integrator_aovs(self.loaded.scene)  # the user's, plus the denoiser's guides
        d["integrator"] = {"type": "motion_path", "max_depth": self.max_depth, "rr_depth": self.settings.rr_depth, "aovs": ",".join(aovs)}
        world_from_camera = trs_matrix(fi.camera[0][0], fi.camera[1][0])
        d["sensor"] = sensor_dict(
            scene.camera,
            world_from_camera,
            float(fi.fov[0]),
            self.settings.resolution,
            self.spp,
            self.settings.filter,
            shutter=(0.0, 1.0),
            sampler="multijitter",
            ortho_width=_ortho(fi),
        )
        static = [o for o in scene.objects if o.name in set(self.static_names)]
        self._add_shapes(d, static, fi, materials)
        self._add_lights(d, fi, skip={i for i, _ in self.moving_lights})
        self._scene = mi.load_dict(d)
        self._params = mi.traverse(self._scene)
        # movers: one rest-frame scene each (scale kept in the rest frame)
        movers = []
        self._mover_scale: dict[str, np.ndarray] = {}
        self._mover_params: dict[str, Any] = {}
        for name in self.mover_names:
            obj = next(o for o in scene.objects if o.name == name)
            t, q, s = fi.objects[name]
            md: dict[str, Any] = {"type": "scene"}
            for k, shape in enumerate(object_shapes(obj, self.loaded, np.diag([*s[0], 1.0]), materials)):
                md[f"{name}__{k}"] = shape
            movers.append(mi.load_dict(md))
            self._mover_scale[name] = np.array(s[0])
            self._mover_params[name] = mi.traverse(movers[-1])
        self._movers = movers
        self._scene.integrator().set_movers(movers, fi.samples)
        self._scene.integrator().set_lights([(light.type, mi.load_dict(unit_light_dict(light))) for _, light in self.moving_lights])
        w, h = self.settings.resolution
        if scene.camera.type == "orthographic":
            self._scene.integrator().set_projection("orthographic", w / scene.camera.ortho_width, w, h)
        else:
            x_fov = float(np.asarray(self._params["sensor.x_fov"]).ravel()[0]) if "sensor.x_fov" in self._params else float(fi.fov[0])
            self._scene.integrator().set_projection("perspective", (w / 2) / np.tan(np.radians(x_fov) / 2), w, h)
        self._groups = [self._build_group(name, fi, materials) for name in self.slice_names]
        self._scene.integrator().set_slices([g.scenes for g in self._groups])
        # route the sensor pose through the same parameter update warm frames use, so the
        # first warm frame replays the cold frame's kernels instead of compiling new ones
        self._update(fi)

    def _add_shapes(self, d: dict[str, Any], objects: Any, fi: StackedFrame, materials: dict[str, Any], u: float | None = None) -> None:
        """The visible `objects`' shapes at the frame time (u None) or at shutter fraction u."""
        for obj in objects:
            if not obj.visible:
                continue
            t, q, s = fi.objects[obj.name]
            ot, oq = (t[0], q[0]) if u is None else resample(t[1:], q[1:], u)
            for k, shape in enumerate(object_shapes(obj, self.loaded, trs_matrix(ot, oq, s[0]), materials)):
                d[f"{obj.name}__{k}"] = shape

    def _add_lights(self, d: dict[str, Any], fi: StackedFrame, u: float | None = None, skip: set[int] = set()) -> None:
        """Every light (but those in `skip`) at the frame's time (u None) or at shutter
        fraction u, placed by its baked world_from_light frame."""
        for i, light in enumerate(self.loaded.scene.lights):
            if i in skip:
                continue
            key = light.name or f"light{i}"
            pose = fi.lights.get(key)
            m = None
            if pose is not None:
                lt, lq = (pose[0][0], pose[1][0]) if u is None else resample(pose[0][1:], pose[1][1:], u)
                m = trs_matrix(lt, lq, pose[2][0])
            scalars = {k: _first(v) for k, v in fi.light_scalars.get(key, {}).items()}
            d[key.replace(".", "_")] = light_dict(light, self.loaded, m, scalars)

    def _build_group(self, name: str, fi: StackedFrame, materials: dict[str, Any]) -> Any:
        from .build import DEFAULT_MATERIAL
        from .slices import build_group

        mi = self._mi
        obj = next(o for o in self.loaded.scene.objects if o.name == name)
        bsdf = mi.load_dict(materials.get(obj.material, DEFAULT_MATERIAL) if obj.material else DEFAULT_MATERIAL)
        slices = self._slice_count(fi)
        if isinstance(obj, Particles):
            n = fi.particles[name][0].shape[1] if name in fi.particles else 0
            capacity = max(64, 1 << int(np.ceil(np.log2(max(n, 1) * 1.5))))
            return build_group(mi, name, "particles", capacity, np.zeros((0, 3)), bsdf, slices, radius=obj.radius)
        from ..motion.deform import bind_mesh

        verts, faces = bind_mesh(self.loaded, obj)
        return build_group(mi, name, "deform", len(verts), np.asarray(faces, np.uint32), bsdf, slices)

    def _split_aovs(self, image: np.ndarray) -> np.ndarray:
        """RGBA from the film's output; the AOV channels go to `self.last_aovs` as layers
        named for the EXR: Z [H, W], N [H, W, 3], motion [H, W, 2], albedo [H, W, 3].
        The integrator's channel names (`aov_names`, in its own order) are the one table:
        `layer.C` channels group into one layer, a bare name is a one-channel layer."""
        self.last_aovs = {}
        names = self._scene.integrator().aov_names()
        layers: dict[str, list[int]] = {}
        for k, name in enumerate(names):
            layers.setdefault(name.split(".")[0], []).append(4 + k)
        for layer, index in layers.items():
            self.last_aovs[layer] = image[..., index[0]] if len(index) == 1 and "." not in names[index[0] - 4] else image[..., index]
        return image[..., :4]

    def _slice_count(self, fi: StackedFrame) -> int:
        return max(1, min(self.settings.time_slices, fi.samples))

    def _update_groups(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> None:
        """Each slice's geometry at its time: slice s of S holds the baked sample nearest
        u = s / (S - 1) (all at one instant for `off` and for one sub-frame)."""
        from .slices import particle_mesh, update_group

        n = fi.samples
        count = self._slice_count(fi)
        if mode == "off":
            index = [0] * count
        elif u_fixed is not None:
            index = [1 + int(round(u_fixed * (n - 1)))] * count
        elif count == 1:
            index = [0]
        else:
            index = [1 + int(round(s * (n - 1) / (count - 1))) for s in range(count)]
        for g in self._groups:
            per_slice = []
            if g.kind == "particles":
                positions, alive = fi.particles.get(g.name, (np.zeros((n + 1, 0, 3)), np.zeros((n + 1, 0), bool)))
                if positions.shape[1] > g.capacity:  # more particles than room: grow (one recompile)
                    self._grow(g, positions.shape[1], fi)
                    return self._update_groups(fi, mode, u_fixed)
                for i in index:
                    per_slice.append(particle_mesh(positions[i], alive[i], g.radius, g.capacity)[0])
            else:
                t, q, s = fi.objects[g.name]
                local = fi.vertices[g.name]
                for i in index:
                    per_slice.append(quat_rotate(q[i], local[i] * s[i]) + t[i])
            update_group(self._mi, g, per_slice)

    def _grow(self, group: Any, needed: int, fi: StackedFrame) -> None:
        from .slices import build_group

        k = self._groups.index(group)
        capacity = 1 << int(np.ceil(np.log2(needed * 1.5)))
        bsdf = group.scenes[0].shapes()[0].bsdf()
        self._groups[k] = build_group(self._mi, group.name, "particles", capacity, group.faces, bsdf, len(group.scenes), radius=group.radius)
        self._scene.integrator().set_slices([g.scenes for g in self._groups])

    # --- per frame (warm) ---------------------------------------------------------------

    def _update(self, fi: StackedFrame) -> tuple[str, ...]:
        """Per-frame parameter changes: the sensor only (moving lights are per frame too).
        Returns the keys changed; shapes of the static set never appear here, so its BVH
        is never rebuilt."""
        params = self._params
        camera = self.loaded.scene.camera
        world_from_camera = trs_matrix(fi.camera[0][0], fi.camera[1][0])
        sensor = sensor_dict(camera, world_from_camera, float(fi.fov[0]), self.settings.resolution, self.spp, self.settings.filter, ortho_width=_ortho(fi))
        changed: list[str] = []
        if "sensor.to_world" in params:
            params["sensor.to_world"] = sensor["to_world"]
            changed.append("sensor.to_world")
        if camera.type == "perspective" and "sensor.x_fov" in params and float(params["sensor.x_fov"][0]) != float(fi.fov[0]):
            params["sensor.x_fov"] = float(fi.fov[0])
            changed.append("sensor.x_fov")
        changed += self._update_lights(fi)
        if changed:
            params.update()
        changed += self._update_mover_scales(fi)
        return tuple(changed)

    def _update_lights(self, fi: StackedFrame) -> list[str]:
        """Animated lights at the frame's time: build the light as it is now and copy its
        parameters into the scene (opaque, so new values replay the same kernels)."""
        dr, mi = self._dr, self._mi
        keys: list[str] = []
        for i, light in self._animated_lights:
            key = light.name or f"light{i}"
            pose = fi.lights.get(key)
            m = trs_matrix(pose[0][0], pose[1][0], pose[2][0]) if pose is not None else None
            scalars = {k: _first(v) for k, v in fi.light_scalars.get(key, {}).items()}
            fresh = mi.traverse(mi.load_dict(light_dict(light, self.loaded, m, scalars)))
            prefix = key.replace(".", "_")
            for k in fresh.keys():
                target = f"{prefix}.{k}"
                if target in self._params and not k.endswith("data"):  # never copy an envmap's pixels
                    value = fresh[k]
                    if hasattr(value, "index"):
                        dr.make_opaque(value)
                    self._params[target] = value
                    keys.append(target)
        return keys

    def _update_mover_scales(self, fi: StackedFrame) -> list[str]:
        """A mover's scale is applied in its rest frame, per frame (not per sample): only
        that mover's small BVH is rebuilt, and only when its scale changed."""
        keys: list[str] = []
        scene = self.loaded.scene
        for name in self.mover_names:
            s = np.asarray(fi.objects[name][2][0], dtype=float)
            if np.allclose(s, self._mover_scale[name]):
                continue
            obj = next(o for o in scene.objects if o.name == name)
            params = self._mover_params[name]
            for k, shape in enumerate(object_shapes(obj, self.loaded, np.diag([*s, 1.0]), {})):
                params[f"{name}__{k}.to_world"] = shape["to_world"]
                keys.append(f"mover:{name}__{k}.to_world")
            params.update()
            self._mover_scale[name] = s
        return keys

    def _integrator_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None = None) -> None:
        n = fi.samples
        m = len(self.mover_names)
        mt = np.zeros((m, n, 3))
        mq = np.zeros((m, n, 4))
        for k, name in enumerate(self.mover_names):
            t, q, _ = fi.objects[name]
            if mode == "off":
                mt[k], mq[k] = t[0], q[0]
            elif u_fixed is not None:
                tt, qq = resample(t[1:], q[1:], u_fixed)
                mt[k], mq[k] = tt, qq
            else:
                mt[k], mq[k] = t[1:], q[1:]
        ct, cq = fi.camera
        q_frame_inv = cq[0] * np.array([1, -1, -1, -1])
        if mode == "off":
            cam_t = np.repeat(ct[:1], n, axis=0)
            cam_q = np.repeat(cq[:1], n, axis=0)
        elif u_fixed is not None:
            tt, qq = resample(ct[1:], cq[1:], u_fixed)
            cam_t, cam_q = np.repeat(tt[None], n, axis=0), np.repeat(qq[None], n, axis=0)
        else:
            cam_t, cam_q = ct[1:], cq[1:]
        rel = quat_mul(cam_q, q_frame_inv[None, :])
        lt, lq, rgb = self._moving_light_frame(fi, mode, u_fixed)
        self._scene.integrator().set_frame(mt, mq, cam_t, rel, ct[0], cam_q, lt, lq, rgb)
        if self._groups:
            self._update_groups(fi, mode, u_fixed)

    def _moving_light_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The moving lights' world_from_light across the shutter ([L, N, 3], [L, N, 4],
        as the movers': all at the frame time for `off`, all at u for one sub-frame) and
        their colours at the frame's time ([L, 3])."""
        n = fi.samples
        count = len(self.moving_lights)
        lt, lq, rgb = np.zeros((count, n, 3)), np.zeros((count, n, 4)), np.zeros((count, 3))
        for k, (i, light) in enumerate(self.moving_lights):
            key = light.name or f"light{i}"
            t, q, _ = fi.lights[key]
            if mode == "off":
                lt[k], lq[k] = t[0], q[0]
            elif u_fixed is not None:
                lt[k], lq[k] = resample(t[1:], q[1:], u_fixed)
            else:
                lt[k], lq[k] = t[1:], q[1:]
            value = fi.light_scalars.get(key, {}).get(LIGHT_CHANNEL[light.type])
            rgb[k] = np.asarray(value[0] if value is not None else getattr(light, LIGHT_CHANNEL[light.type]), dtype=float)
        return lt, lq, rgb

    def _full_scene(self, fi: StackedFrame, u: float | None) -> Any:
        """The whole scene at one instant (u = shutter fraction, None = the frame time),
        with Mitsuba's `path` integrator: the scalar fallback and its sub-frames."""
        return self._mi.load_dict(self._full_scene_dict(fi, u))

    def _full_scene_dict(self, fi: StackedFrame, u: float | None) -> dict[str, Any]:
        """The Mitsuba dictionary of `_full_scene` (rigid objects and lights; particle
        systems and deforming meshes are the renderer's own geometry and are not in it)."""
        scene = self.loaded.scene
        materials = {m.name: material_dict(m, self.loaded) for m in scene.materials}
        d: dict[str, Any] = {"type": "scene", "integrator": {"type": "path", "max_depth": self.max_depth, "rr_depth": self.settings.rr_depth}}

        def pose(t: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return (t[0], q[0]) if u is None else resample(t[1:], q[1:], u)

        ct, cq = pose(*fi.camera)
        d["sensor"] = sensor_dict(scene.camera, trs_matrix(ct, cq), float(fi.fov[0]), self.settings.resolution, self.spp, self.settings.filter, ortho_width=_ortho(fi))
        self._add_shapes(d, scene.objects, fi, materials, u)
        self._add_lights(d, fi, u)
        return d

    def _render_scalar(self, fi: StackedFrame, mode: str, seed: int) -> Any:
        mi = self._mi
        if mode == "off":
            return mi.render(self._full_scene(fi, None), seed=seed, spp=self.spp)
        k = self.settings.subframes
        spp = max(1, self.spp // k)
        acc = None
        for j in range(k):
            img = mi.render(self._full_scene(fi, (j + 0.5) / k), seed=(seed * 7919 + j) & 0x7FFFFFFF, spp=spp)
            acc = img if acc is None else acc + img
        return acc / k

    def render(self, frame: BakedFrame, mode: str | None = None) -> tuple[np.ndarray, FrameStats]:
        """Render one baked frame; returns RGBA float32 [H, W, 4] and its stats."""
        fi = stack_frame(frame)
        from . import assets

        dr, mi = self._dr, self._mi
        mode = mode or self.settings.motion_blur
        if not self.vectorized:
            t0 = time.perf_counter()
            seed = frame_seed(self.settings.seed, fi.frame, self.settings.seed_policy)
            img = self._render_scalar(fi, mode, seed)
            rgba = np.array(img, dtype=np.float32)
            if rgba.shape[2] == 3:
                rgba = np.concatenate([rgba, np.ones(rgba.shape[:2] + (1,), np.float32)], axis=2)
            cold = self._frames_done == 0
            self._frames_done += 1
            return rgba, FrameStats(fi.frame, cold, 0.0, time.perf_counter() - t0, 0, 0, 0, False)
        hits0 = assets.STATS["hits"]
        t0 = time.perf_counter()
        cold = self._scene is None
        updated: tuple[str, ...] = ()
        if cold:
            try:
                self._build(fi)
            except BaseException:
                self._scene = None  # never keep a half-built scene
                raise
        else:
            updated = self._update(fi)
        seed = frame_seed(self.settings.seed, fi.frame, self.settings.seed_policy)
        dr.kernel_history()  # clear
        setup_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        if mode == "subframes":
            k = self.settings.subframes
            spp = max(1, self.spp // k)
            acc = None
            for j in range(k):
                self._integrator_frame(fi, mode, u_fixed=(j + 0.5) / k)
                img = mi.render(self._scene, seed=(seed * 7919 + j) & 0x7FFFFFFF, spp=spp)
                acc = img if acc is None else acc + img
            img = acc / k
        else:
            self._integrator_frame(fi, mode)
            img = mi.render(self._scene, seed=seed, spp=self.spp)
        dr.eval(img)
        dr.sync_thread()
        rgba = np.array(img, dtype=np.float32)
        render_s = time.perf_counter() - t1
        rgba = self._split_aovs(rgba)
        history = dr.kernel_history()
        self._last_history = [h for h in history if h.get("type") == dr.KernelType.JIT]
        compiled = sum(1 for h in history if h.get("type") == dr.KernelType.JIT and not h.get("cache_hit", False))
        reused = sum(1 for h in history if h.get("type") == dr.KernelType.JIT and h.get("cache_hit", False))
        if rgba.shape[2] == 3:
            rgba = np.concatenate([rgba, np.ones(rgba.shape[:2] + (1,), np.float32)], axis=2)
        self._frames_done += 1
        return rgba, FrameStats(
            frame=fi.frame,
            cold=cold,
            setup_s=setup_s,
            render_s=render_s,
            kernels_compiled=compiled,
            kernels_reused=reused,
            asset_cache_hits=assets.STATS["hits"] - hits0,
            scene_reused=not cold,
            updated_params=updated,
        )


def _ortho(fi: StackedFrame) -> float | None:
    """The orthographic width at the frame's time, if the camera is orthographic."""
    return None if fi.ortho_width is None else float(fi.ortho_width[0])


def _first(values: np.ndarray) -> Any:
    """The frame-time value of an animated scalar or colour channel."""
    v = np.asarray(values)[0]
    return float(v) if np.ndim(v) == 0 else tuple(float(x) for x in np.ravel(v))
