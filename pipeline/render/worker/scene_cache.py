"""The first-frame cache of one worker: the Mitsuba scene built once per (scene, settings)
on the cold frame, and the little that changes per warm frame.

Cold (`SceneCache.build`): the static set and its BVH (through the shared disk cache of
converted assets), the atlas of the rigid movers' rest-frame shapes and the particle
systems' holder spheres and the deforming meshes' templates (render/kernel/atlas.py), the
moving lights' unit emitters, and the integrator's job state. Warm (`update`, then
`set_frame`): the sensor's pose and field of view (a parameter update that rebuilds no
BVH), animated environment lights' parameters, the atlas again where a mover's scale
changed, the per-frame poses of movers, particles, camera and moving lights (one opaque
array read by the integrator: no recompilation), the broadphase's proxies (one buffer, one
BVH build: render/kernel/broadphase.py), and the deforming meshes' templates (render/translate/deforming.py).
"""

from __future__ import annotations

import weakref

from typing import TYPE_CHECKING, Any

import numpy as np

from ...motion.pose import quat_mul
from ...scene.lights import light_key
from ...scene.loader import LoadedScene
from ...variant import load_dict
from ..kernel.atlas import Atlas, analytic
from ..kernel.broadphase import EMPTY_BOX, Broadphase, far_proxies, in_regions, parts, worth_parts, particle_proxies, reach, separate, sphere_proxies, swept_spheres
from ..translate.build import dressed, material_dict, mitsuba_id, object_shapes, unit_light_dict
from ..output.denoise import integrator_aovs
from ..translate.instant import add_lights, add_shapes, light_record, sensor_record
from ..translate.roles import Roles
from ..kernel.sbt import SbtOwner, dict_types
from ..poses.shutter import across_shutter, particles_across_shutter
from ..kernel.lights import MovingEmitters, moving_emitter_tables
from ..translate.deforming import DeformingMeshes

if TYPE_CHECKING:
    from ..poses.stacked import StackedFrame


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
        self._mover_stretch = np.zeros((0, 3, 3))  # [M, 3, 3] each mover's stretch baked into its atlas shapes
        self._materials: dict[str, Any] = {}
        self.atlas: Atlas | None = None
        self.broadphase: Broadphase | None = None
        self._capacity: list[int] = []  # particles' room per system (grows by 1.5x: one recompile)
        self._moving_changed = True  # the atlas or broadphase scene changed: tell the integrator
        self._reach = 1e-3  # how far behind a ray the broadphase walk starts (broadphase.reach)
        self._proxy_box = EMPTY_BOX  # the box holding every live proxy (broadphase.union_box)
        self._regions = np.array([1.0, 0.0])  # the shutter's parts and their regions' spacing (broadphase.in_regions)
        self.deforming: DeformingMeshes | None = None  # deforming meshes: movers of the atlas (render/translate/deforming.py)
        self.owner: SbtOwner | None = None  # the SBT owner of every scene the kernel traces

    @property
    def integrator(self) -> Any:
        """The scene's motion_path integrator."""
        return self.scene.integrator()

    # --- build (cold) -----------------------------------------------------------------

    def build(self, fi: StackedFrame, mode: str = "stochastic") -> None:
        """Build everything that is kept across frames, from the first frame this worker
        renders (in motion-blur `mode`); on failure nothing half-built is kept."""
        try:
            self._build(fi, mode)
        except BaseException:
            self.scene = None  # never keep a half-built scene
            raise

    def _build(self, fi: StackedFrame, mode: str) -> None:
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
        from ..kernel.film import stratified_passes  # (film imports drjit: not at module level, which the farm's main process imports)

        d["sensor"] = sensor_record(loaded, stratified_passes(self.spp, self.spp)[0], fi, shutter=(0.0, 1.0), sampler="multijitter")
        static = [o for o in scene.objects if o.name in set(self.roles.static_names)]
        add_shapes(d, loaded, static, fi, materials)
        add_lights(d, loaded, fi, skip=frozenset(i for i, _ in self.roles.moving_lights))
        # every scene the kernel traces is built against one SBT owner covering their
        # shape types (render/kernel/sbt.py: on CUDA the others' traces would be disabled)
        self._materials = materials
        self._mover_stretch = fi.stretch_at_frame(self.roles.mover_names)
        mover_dicts = self._all_mover_dicts()
        types = set().union(dict_types(d), *(dict_types({str(k): v for k, v in enumerate(md)}) for md in mover_dicts))
        if self.roles.deforming_names:
            types.add("Mesh")
        if self.roles.particle_names:
            types.add("Sphere")
        if self.roles.mover_names or self.roles.particle_names or self.roles.deforming_names:
            types.add("Ellipsoids")
        self.owner = SbtOwner(types)
        self.scene = self.owner.scene(d)
        # the integrator holds the job's other scenes and their owner, which holds this
        # scene, which holds the integrator from C++: a cycle the collector cannot break
        # (not at the interpreter's exit: the process's memory goes anyway, and Mitsuba's
        # module may be half torn down by then)
        weakref.finalize(self, self.scene.integrator().release).atexit = False
        self._params = mi.traverse(self.scene)
        integrator = self.integrator
        integrator.set_sbt_owner(self.owner)
        integrator.set_samples(fi.samples)
        self.atlas = Atlas(mi, self.owner.scene)
        self.broadphase = Broadphase(mi, self.owner.scene)
        self._capacity = [_room(_particle_count(fi, name)) for name in self.roles.particle_names]
        if self.roles.deforming_names:
            self.deforming = DeformingMeshes(mi, loaded, list(self.roles.deforming_names), fi, materials)
            self.deforming.draw(fi, mode, None)
        self._build_atlas(mover_dicts)
        integrator.set_lights([load_dict(unit_light_dict(light, loaded)) for _, light in self.roles.moving_lights])
        w, h = settings.resolution
        if scene.camera.type == "orthographic":
            integrator.set_projection("orthographic", w / scene.camera.ortho_width, w, h)
        else:
            x_fov = float(np.asarray(self._params["sensor.x_fov"]).ravel()[0]) if "sensor.x_fov" in self._params else float(fi.fov[0])
            integrator.set_projection("perspective", (w / 2) / np.tan(np.radians(x_fov) / 2), w, h)
        # route the sensor pose through the same parameter update warm frames use, so the
        # first warm frame replays the cold frame's kernels instead of compiling new ones
        self.update(fi, mode)

    def _mover_dicts(self, k: int) -> list[dict[str, Any]]:
        """Mover k's shape dictionaries in its rest frame, its stretch baked in."""
        obj = self.loaded.objects_by_name[self.roles.mover_names[k]]
        stretch = np.eye(4)
        stretch[:3, :3] = self._mover_stretch[k]
        return object_shapes(obj, self.loaded, stretch, self._materials)

    def _all_mover_dicts(self) -> list[list[dict[str, Any]]]:
        """Every mover's shape dictionaries (`_mover_dicts`), in order."""
        return [self._mover_dicts(k) for k in range(len(self.roles.mover_names))]

    def _holder_dicts(self, name: str) -> list[dict[str, Any]]:
        """A particle system's holder: one sphere of the particles' radius at the origin,
        wearing their material (and emitter); every particle is this sphere, moved."""
        obj = self.loaded.objects_by_name[name]
        return [dressed({"type": "sphere", "radius": float(obj.radius)}, obj, self.loaded, self._materials)]

    def _build_atlas(self, mover_dicts: list[list[dict[str, Any]]]) -> None:
        """The atlas of every mover (at its current scale), particle holder and deforming
        mesh's templates (at what they show now), in that order."""
        atlas = self.atlas
        if atlas is None:
            return
        holders = [self._holder_dicts(name) for name in self.roles.particle_names]
        dicts: list[list[dict[str, Any]] | None] = [*mover_dicts, *holders]
        templates: list[list[Any] | None] = [None if analytic(md) else [load_dict(sd) for sd in md] for md in dicts]  # type: ignore[arg-type]  # (analytic ones: bounded and built in the atlas from their dictionaries)
        keys = [f"m{k}_{mitsuba_id(n)}" for k, n in enumerate(self.roles.mover_names)] + [f"p{k}_{mitsuba_id(n)}" for k, n in enumerate(self.roles.particle_names)]
        if self.deforming is not None:
            shapes = self.deforming.shapes()
            templates += shapes
            dicts += [None] * len(shapes)
            keys += [f"d{k}_{s}_{mitsuba_id(g.name)}" for k, g in enumerate(self.deforming.meshes) for s in range(self.deforming.templates_of(g))]
        if templates:
            if atlas.scene is not None and self.owner is not None:
                self.owner.forget([atlas.scene])  # the old atlas is no longer traced
            atlas.build(templates, keys, dicts)

    # --- per frame (warm) ---------------------------------------------------------------

    def update(self, fi: StackedFrame, mode: str = "stochastic") -> tuple[str, ...]:
        """Per-frame parameter changes: the sensor, animated environment lights, mover
        scales and the broadphase for motion-blur `mode`. Returns the keys changed; shapes
        of the static set never appear here, so its BVH is never rebuilt."""
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
        self._update_broadphase(fi, mode)  # a scene update, before the render: its kernels are the update's
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
        parent scale: `instant.rest_frame`) is baked into its atlas shapes, per frame (not per
        sample): where any mover's stretch changed, the atlas is laid out and built again."""
        stretches = fi.stretch_at_frame(self.roles.mover_names)  # one stack, compared at once
        changed = np.flatnonzero(~np.isclose(stretches, self._mover_stretch, rtol=1e-5, atol=1e-8).all(axis=(1, 2))) if len(stretches) else []
        if not len(changed):
            return []
        self._mover_stretch = stretches
        names = self.roles.mover_names
        atlas = self.atlas
        # in place where each changed mover still fits its cell (the kernels replay), else
        # the atlas is laid out and built again
        fits = atlas is not None and atlas.scene is not None and all(
            atlas.replace(int(k), [load_dict(sd) for sd in self._mover_dicts(int(k))]) for k in changed
        )
        if not fits:
            self._build_atlas(self._all_mover_dicts())
            self._moving_changed = True
        return [f"mover:{mitsuba_id(names[int(k)])} (atlas)" for k in changed]

    def set_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None = None) -> None:
        """The integrator's per-frame poses (movers, particles, camera, moving lights), the
        broadphase's proxies and the slices' geometry for motion-blur `mode`: the baked
        samples across the shutter, all at the frame's time (`off`), or all at shutter
        fraction `u_fixed` (one sub-frame)."""
        n = fi.samples
        t, q, _ = fi.tracks(self.roles.mover_names)  # every mover at once: no per-mover work
        mt, mq = across_shutter(t, q, n, mode, u_fixed)
        if self.deforming is not None:
            self._draw_deforming(fi, mode, u_fixed)
            dt, dq = self.deforming.tracks(mode, u_fixed, n)
            mt, mq = np.concatenate([mt, dt]), np.concatenate([mq, dq])
        particles = self._particles_frame(fi, mode, u_fixed)
        ct, cq = fi.camera
        q_frame_inv = cq[0] * np.array([1, -1, -1, -1])
        cam_t, cam_q = across_shutter(ct, cq, n, mode, u_fixed)
        rel = quat_mul(cam_q, q_frame_inv[None, :])
        lt, lq, rgb = self._moving_light_frame(fi, mode, u_fixed)
        moving = self._moving_frame(particles)
        self.integrator.set_frame(mt, mq, cam_t, rel, ct[0], cam_q, lt, lq, rgb, moving)
        # every update above evaluated and finished now (the broadphase's BVH build runs on
        # drjit's thread pool): left pending, the render's kernel is traced against work that
        # is done on one frame and not yet on another, and differs between them
        self._dr.eval()
        self._dr.sync_thread()

    def _draw_deforming(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> None:
        """The deforming meshes' templates at what they show for this instant, written into
        the atlas in place (one BVH build), or the atlas built again where one outgrew its
        cell."""
        atlas, deforming = self.atlas, self.deforming
        if atlas is None or deforming is None or atlas.scene is None:
            return
        deforming.draw(fi, mode, u_fixed)
        first = self._deforming_first()
        changing = deforming.changing()
        if not changing:
            return  # (a flock's template never changes)
        if all([atlas.reshape(first + k, p, nrm) for k, p, nrm in changing]):
            atlas.commit()
            return
        self._build_atlas(self._all_mover_dicts())
        self._set_moving()

    def _deforming_first(self) -> int:
        """The atlas index of the first deforming mesh's first template."""
        return len(self.roles.mover_names) + len(self.roles.particle_names)

    def _grow_particles(self, fi: StackedFrame) -> None:
        """The particles' room: a system past its room grows by 1.5x (one recompile)."""
        counts = [_particle_count(fi, name) for name in self.roles.particle_names]
        if any(c > room for c, room in zip(counts, self._capacity)):
            self._capacity = [max(room, _room(c)) for c, room in zip(counts, self._capacity)]

    def _update_broadphase(self, fi: StackedFrame, mode: str) -> None:
        """The broadphase's proxies for one frame in motion-blur `mode`, written as a scene
        update before the render (one buffer, one BVH build). Stochastic blur: one proxy
        per thing and part of the shutter, each part in a region of its own
        (broadphase.parts, in_regions), from the shutter's samples, which the kernel
        interpolates between. `off`: one part, at the frame's time. Sub-frames (where a
        lane's pose is one instant, not its own time's): one part holding every baked row
        (every instant a sub-frame may ask for)."""
        atlas, broad = self.atlas, self.broadphase
        if atlas is None or broad is None or atlas.scene is None:
            return
        self._grow_particles(fi)
        total = int(sum(self._capacity))
        names = self.roles.mover_names
        m = len(names)
        rows = fi.samples + 1
        mt, mq, _ = fi.tracks(names)
        spheres = atlas.layout.sphere[:m]
        if self.deforming is not None:  # movers too, on their fitted tracks, each held with every template it may draw
            self.deforming.fit(fi)
            dt, dq, ds = self.deforming.whole_tracks()
            mt, mq, spheres = np.concatenate([mt, dt]), np.concatenate([mq, dq]), np.concatenate([spheres, ds])
        pp, pa, pr = np.zeros((total, rows, 3)), np.zeros((total, rows), bool), np.zeros(total)
        at = 0
        for k, (name, room) in enumerate(zip(self.roles.particle_names, self._capacity)):
            if name in fi.particles:
                positions, alive = fi.particles[name]
                pp[at:at + positions.shape[1]] = np.swapaxes(positions, 0, 1)
                pa[at:at + positions.shape[1]] = np.swapaxes(alive, 0, 1)
            pr[at:at + room] = atlas.layout.sphere[m + k, 3]
            at += room

        def proxies_over(held: slice, also: bool, some: np.ndarray | None = None) -> np.ndarray:
            """Every thing's proxy over the rows `held` (and the frame's time, row 0); `some`:
            only those particles (indices)."""
            p, a, r = (pp, pa, pr) if some is None else (pp[some], pa[some], pr[some])
            extra = (p[:, 0], a[:, 0]) if also else None
            rigid = swept_spheres(np.concatenate([mt[:, :1], mt[:, held]], axis=1) if also else mt[:, held],
                                  np.concatenate([mq[:, :1], mq[:, held]], axis=1) if also else mq[:, held], spheres)
            return np.concatenate([sphere_proxies(rigid), particle_proxies(p[:, held], a[:, held], r, extra)])

        cuts = parts(fi.samples)
        # the same count of proxies in every mode and frame (B parts of P), so that no new
        # broadphase is built (nor its kernels compiled again); where the lanes walk one
        # part only (one instant drawn: `off`, a sub-frame; or parts that would not be
        # smaller: `worth_parts`) the others are far away, out of every ray's reach
        walked = 1
        if mode == "stochastic" and len(cuts) > 1:
            # decided on a sample of the particles (all of them cost 0.25 s a part at 100,000)
            some = np.linspace(0, total - 1, min(total, 4096)).astype(int) if total else np.zeros(0, int)
            if worth_parts(proxies_over(slice(1, rows), True, some), [proxies_over(slice(1 + i0, 2 + i1), False, some) for i0, i1 in cuts]):
                walked = len(cuts)
        if walked > 1:
            per_part = [proxies_over(slice(1 + i0, 2 + i1), False) for i0, i1 in cuts]
        else:  # `off` draws the frame's time alone; sub-frames any instant of the shutter
            per_part = [proxies_over(slice(0, 1), False) if mode == "off" else proxies_over(slice(1, rows), True)]
        scale = max(self._walk_scale(fi, part) for part in per_part)
        # the regions lie within a few walk scales of the origin: coincident means within
        # float steps there (broadphase.separate)
        per_part = [separate(part, scale * (len(cuts) + 2)) for part in per_part]
        per_part += [far_proxies(len(per_part[0]))] * (len(cuts) - len(per_part))
        proxies, self._proxy_box, spacing = in_regions(per_part)
        self._regions = np.array([float(walked), spacing])
        self._reach = reach(proxies)
        scene_before = broad.scene
        broad.update(proxies)
        if scene_before is not None and broad.scene is not scene_before and self.owner is not None:
            self.owner.forget([scene_before])
        if broad.scene is not scene_before or self._moving_changed or self.integrator.world.particles != total:
            self._set_moving()

    def _set_moving(self) -> None:
        """Give the integrator the broadphase and atlas scenes and what they hold."""
        atlas, broad = self.atlas, self.broadphase
        if atlas is None or broad is None:
            return
        m = len(self.roles.mover_names)
        firsts = [int(f) for f in self._mover_templates()[:, 0]]
        systems, at = [], len(firsts)
        for k, room in enumerate(self._capacity):  # each system: (first proxy, room, holder template)
            systems.append((at, room, m + k))
            at += room
        entries, table, room = moving_emitter_tables(atlas.keys, [e.get_shape().id() for e in atlas.scene.emitters()], firsts, systems, len(atlas.layout.offset))
        emitters = MovingEmitters(atlas.scene, entries, table, room) if entries else None
        self.integrator.set_moving(broad.scene, atlas.scene, len(firsts), int(sum(self._capacity)), emitters)
        self._moving_changed = False

    def _mover_templates(self) -> np.ndarray:
        """Each rigid proxy's (first template, count) [M, 2]: a mover its own template, a
        deforming mesh's movers theirs (the frame data's `mover_template`)."""
        m = len(self.roles.mover_names)
        templates = np.stack([np.arange(m, dtype=float), np.ones(m)], axis=1)
        if self.deforming is not None:
            templates = np.concatenate([templates, self.deforming.mover_templates(self._deforming_first())])
        return templates

    def _particles_frame(self, fi: StackedFrame, mode: str, u_fixed: float | None) -> dict[str, np.ndarray]:
        """The particles across the shutter for motion-blur `mode` (the frame data's
        blocks): centres [C, N, 3], alive [C, N] and each one's template [C]."""
        n = fi.samples
        total = int(sum(self._capacity))
        pp, pa = np.zeros((total, n, 3)), np.zeros((total, n))
        pt = np.zeros(total)
        m = len(self.roles.mover_names)
        at = 0
        for k, (name, room) in enumerate(zip(self.roles.particle_names, self._capacity)):
            if name in fi.particles:
                positions, alive = fi.particles[name]
                p, a = particles_across_shutter(positions, alive, n, mode, u_fixed)
                pp[at:at + len(p)], pa[at:at + len(p)] = p, a
            pt[at:at + room] = m + k
            at += room
        return {"particle_p": pp, "particle_alive": pa, "particle_template": pt}

    def _moving_frame(self, particles: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The atlas's templates, the particles (`_particles_frame`) and the broadphase's
        walk values for the frame data (the broadphase was updated just before)."""
        atlas = self.atlas
        if atlas is None or atlas.scene is None:
            return {}
        return {
            "mover_template": self._mover_templates(),
            "template_offset": atlas.layout.offset,
            "template_box": atlas.layout.box,
            "template_sphere": atlas.layout.sphere,
            **particles,
            "reach": np.array([self._reach]),
            "proxy_box": self._proxy_box,
            "regions": self._regions,
        }

    def _walk_scale(self, fi: StackedFrame, proxies: np.ndarray) -> float:
        """A bound on the distances of a broadphase walk (`broadphase.separate`): twice the
        farthest of the static scene's box, the camera and the live proxies from the
        origin, plus the walk's start behind a ray."""
        box = self.scene.bbox()
        far = float(np.abs(np.concatenate([np.array(box.min, dtype=float).ravel(), np.array(box.max, dtype=float).ravel()])).max()) if box.valid() else 0.0
        live = proxies[np.abs(proxies[:, 0]) < 1e8]
        if len(live):
            far = max(far, float((np.abs(live[:, :3]).max(axis=1) + live[:, 3:6].max(axis=1)).max()))
        far = max(far, float(np.abs(fi.camera[0]).max()))
        return 2.0 * far * np.sqrt(3.0) + reach(proxies)

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


def _particle_count(fi: StackedFrame, name: str) -> int:
    """How many particles a system has in this frame's bake."""
    return int(fi.particles[name][0].shape[1]) if name in fi.particles else 0


def _room(count: int) -> int:
    """Room for `count` particles: a power of two with half as many again to spare, at
    least 64, so a growing system recompiles rarely."""
    return max(64, 1 << int(np.ceil(np.log2(max(count, 1) * 1.5))))
