"""The first-frame cache of one worker: the Mitsuba scene built once per (scene, settings)
on the cold frame, and the little that changes per warm frame.

Cold (`SceneCache.build`): the static set and its BVH (through the shared disk cache of
converted assets), the rigid movers' rest-frame scenes, the moving lights' unit emitters,
the time-sliced groups, and the integrator's job state. Warm (`update`, then `set_frame`):
the sensor's pose and field of view (a parameter update that rebuilds no BVH), animated
environment lights' parameters, a mover's scale where it changed (only that mover's small
BVH), and the per-frame poses of movers, camera and moving lights (one opaque array read
by the integrator: no BVH rebuild, no recompilation), plus the slices' vertices.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..motion.pose import quat_mul
from ..scene.lights import light_key
from ..scene.loader import LoadedScene
from ..variant import load_dict
from .build import material_dict, mitsuba_id, object_shapes, unit_light_dict
from .denoise import integrator_aovs
from .instant import add_lights, add_shapes, light_record, rest_frame, sensor_record
from .roles import Roles
from .sbt import SbtOwner, dict_types
from .shutter_poses import across_shutter
from .slices import SlicedGeometry

if TYPE_CHECKING:
    from .stacked import StackedFrame


class SceneCache:
    """The motion_path scene of one job in one worker process (LLVM or CUDA variants)."""

    def __init__(self, mi: Any, dr: Any, loaded: LoadedScene, roles: Roles, spp: int, max_depth: int) -> None:
        self._mi, self._dr = mi, dr
        self.loaded = loaded
        self.roles = roles
        self.spp = spp
        self.max_depth = max_depth
        self.scene: Any = None  # None until the cold frame is built
        self._params: Any = None
        self._movers: list[Any] = []
        self._mover_scale: dict[str, np.ndarray] = {}
        self._mover_params: dict[str, Any] = {}
        self.sliced: SlicedGeometry | None = None
        self.owner: SbtOwner | None = None  # the SBT owner of every scene the kernel traces

    @property
    def integrator(self) -> Any:
        """The scene's motion_path integrator."""
        return self.scene.integrator()

    # --- build (cold) -----------------------------------------------------------------

    def build(self, fi: StackedFrame) -> None:
        """Build everything that is kept across frames, from the first frame this worker
        renders; on failure nothing half-built is kept."""
        try:
            self._build(fi)
        except BaseException:
            self.scene = None  # never keep a half-built scene
            raise

    def _build(self, fi: StackedFrame) -> None:
        mi = self._mi
        loaded = self.loaded
        scene = loaded.scene
        settings = scene.render
        materials = {m.name: load_dict(material_dict(m, loaded)) for m in scene.materials}
        d: dict[str, Any] = {"type": "scene"}
        aovs = integrator_aovs(scene)  # the user's, plus the denoiser's guides
        d["integrator"] = {"type": "motion_path", "max_depth": self.max_depth, "rr_depth": settings.rr_depth, "aovs": ",".join(aovs)}
        # the sampler's count is set per pass by the film (film.stratified_passes); built with
        # one it takes as it is, so Mitsuba does not warn of a rounding that never happens
        from .film import stratified_passes  # (film imports drjit: not at module level, which the farm's main process imports)

        d["sensor"] = sensor_record(loaded, stratified_passes(self.spp, self.spp)[0], fi, shutter=(0.0, 1.0), sampler="multijitter")
        static = [o for o in scene.objects if o.name in set(self.roles.static_names)]
        add_shapes(d, loaded, static, fi, materials)
        add_lights(d, loaded, fi, skip=frozenset(i for i, _ in self.roles.moving_lights))
        # movers: one rest-frame scene each (scale kept in the rest frame)
        mover_dicts: list[dict[str, Any]] = []
        self._mover_scale = {}
        for name in self.roles.mover_names:
            obj = next(o for o in scene.objects if o.name == name)
            t, q, s = fi.objects[name]
            md: dict[str, Any] = {"type": "scene"}
            for k, shape in enumerate(object_shapes(obj, loaded, np.diag([*s[0], 1.0]), materials)):
                md[f"{mitsuba_id(name)}__{k}"] = shape
            mover_dicts.append(md)
            self._mover_scale[name] = np.array(s[0])
        # every scene the kernel traces is built against one SBT owner covering their
        # shape types (render/sbt.py: on CUDA the others' traces would be disabled)
        types = set().union(dict_types(d), *(dict_types(md) for md in mover_dicts), {"Mesh"} if self.roles.slice_names else set())
        self.owner = SbtOwner(types)
        self.scene = self.owner.scene(d)
        self._params = mi.traverse(self.scene)
        movers = [self.owner.scene(md) for md in mover_dicts]
        self._mover_params = {name: mi.traverse(m) for name, m in zip(self.roles.mover_names, movers)}
        self._movers = movers
        integrator = self.integrator
        integrator.set_sbt_owner(self.owner)
        integrator.set_movers(movers, fi.samples)
        integrator.set_lights([load_dict(unit_light_dict(light, loaded)) for _, light in self.roles.moving_lights])
        w, h = settings.resolution
        if scene.camera.type == "orthographic":
            integrator.set_projection("orthographic", w / scene.camera.ortho_width, w, h)
        else:
            x_fov = float(np.asarray(self._params["sensor.x_fov"]).ravel()[0]) if "sensor.x_fov" in self._params else float(fi.fov[0])
            integrator.set_projection("perspective", (w / 2) / np.tan(np.radians(x_fov) / 2), w, h)
        self.sliced = SlicedGeometry(mi, loaded, self.roles.slice_names, fi, materials, integrator.set_slices, self.owner)
        # route the sensor pose through the same parameter update warm frames use, so the
        # first warm frame replays the cold frame's kernels instead of compiling new ones
        self.update(fi)

    # --- per frame (warm) ---------------------------------------------------------------

    def update(self, fi: StackedFrame) -> tuple[str, ...]:
        """Per-frame parameter changes: the sensor, animated environment lights and mover
        scales. Returns the keys changed; shapes of the static set never appear here, so
        its BVH is never rebuilt."""
        params = self._params
        camera = self.loaded.scene.camera
        sensor = sensor_record(self.loaded, self.spp, fi)
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
        parameters into the scene (opaque, so new values replay the same kernels). An
        environment map is built around a 2x1 stand-in image: its pixels are never copied,
        so a warm frame does not read and decode the map's file again."""
        dr, mi = self._dr, self._mi
        keys: list[str] = []
        for i, light in self.roles.animated_lights:
            record = light_record(self.loaded, i, light, fi)
            if "filename" in record:
                record = {k: v for k, v in record.items() if k != "filename"}
                record["bitmap"] = mi.Bitmap(np.ones((1, 2, 3), dtype=np.float32))
            fresh = mi.traverse(load_dict(record))
            prefix = mitsuba_id(light_key(light, i))
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
        """A mover's stretch (its scale, or the full symmetric stretch under a non-uniform
        parent scale) is applied in its rest frame, per frame (not per sample): only that
        mover's small BVH is rebuilt, and only when its stretch changed."""
        keys: list[str] = []
        scene = self.loaded.scene
        for name in self.roles.mover_names:
            s = rest_frame(fi, name)
            before = self._mover_scale[name]
            if np.allclose(s, np.diag([*before, 1.0]) if before.ndim == 1 else before):
                continue
            obj = next(o for o in scene.objects if o.name == name)
            params = self._mover_params[name]
            for k, shape in enumerate(object_shapes(obj, self.loaded, s, {})):
                prefix = f"{mitsuba_id(name)}__{k}"
                if f"{prefix}.to_world" in params:
                    params[f"{prefix}.to_world"] = shape["to_world"]
                    keys.append(f"mover:{prefix}.to_world")
                    continue
                # a mesh (cube, mesh file) holds its transform in its vertices: the fresh shape's
                fresh = self._mi.traverse(load_dict(shape))
                for field in ("vertex_positions", "vertex_normals"):
                    if field in fresh and f"{prefix}.{field}" in params:
                        params[f"{prefix}.{field}"] = fresh[field]
                        keys.append(f"mover:{prefix}.{field}")
            params.update()
            self._mover_scale[name] = s
        return keys

    def set_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None = None) -> None:
        """The integrator's per-frame poses (movers, camera, moving lights) and the slices'
        geometry for motion-blur `mode`: the baked samples across the shutter, all at the
        frame's time (`off`), or all at shutter fraction `u_fixed` (one sub-frame)."""
        n = fi.samples
        m = len(self.roles.mover_names)
        mt = np.zeros((m, n, 3))
        mq = np.zeros((m, n, 4))
        for k, name in enumerate(self.roles.mover_names):
            t, q, _ = fi.objects[name]
            mt[k], mq[k] = across_shutter(t, q, n, mode, u_fixed)
        ct, cq = fi.camera
        q_frame_inv = cq[0] * np.array([1, -1, -1, -1])
        cam_t, cam_q = across_shutter(ct, cq, n, mode, u_fixed)
        rel = quat_mul(cam_q, q_frame_inv[None, :])
        lt, lq, rgb = self._moving_light_frame(fi, mode, u_fixed)
        self.integrator.set_frame(mt, mq, cam_t, rel, ct[0], cam_q, lt, lq, rgb)
        if self.sliced is not None and self.sliced.groups:
            self.sliced.update(fi, mode, u_fixed)

    def _moving_light_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The moving lights' world_from_light across the shutter ([L, N, 3], [L, N, 4],
        as the movers') and their colours at the frame's time ([L, 3])."""
        n = fi.samples
        count = len(self.roles.moving_lights)
        lt, lq, rgb = np.zeros((count, n, 3)), np.zeros((count, n, 4)), np.zeros((count, 3))
        for k, (i, light) in enumerate(self.roles.moving_lights):
            key = light_key(light, i)
            t, q, _ = fi.lights[key]
            lt[k], lq[k] = across_shutter(t, q, n, mode, u_fixed)
            value = fi.light_scalars.get(key, {}).get(light.channel)
            rgb[k] = np.asarray(value[0] if value is not None else light.emission, dtype=float)
        return lt, lq, rgb

    def render(self, seed: int, spp: int, rows: tuple[int, int] = (0, 1)) -> Any:
        """The image of the frame last given to `set_frame` (RGBA + AOV channels); `rows`
        (offset, step): the image rows drawn, a field's with `--fields` (film.render)."""
        self.integrator.set_rows(rows)
        return self._mi.render(self.scene, seed=seed, spp=spp)
