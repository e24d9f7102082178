"""USD (.usd, .usda, .usdc) -> scene records through usd-core (docs/imports.md).

The subset a layout or animation department hands over: Xform (and every Xformable)
hierarchies with time-sampled transforms, Mesh prims (time-sampled points become
blend shapes), UsdGeomCamera, UsdLux distant / sphere / rect / dome lights and
UsdPreviewSurface materials. Time codes become seconds through the stage's
timeCodesPerSecond (time code 0 is scene time 0, plus the import's `time_offset`).

Transforms are keyed at the union of their ops' sample times as translate / rotate
(quaternion, slerp) / scale: exact at the samples, and between them exact for
translate, orient (USD slerps quaternions) and scale ops and for rotations about one
axis; USD lerps multi-axis Euler angles, which slerp only approximates between samples.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .expansion import Expansion, ImportFileError, Origin, SpecError, import_frames
from ..files import file_digest
from ...limits import MAX_USD_LAYER_BYTES as MAX_LAYER_BYTES
from ...limits import MAX_USD_POINT_SAMPLES, MAX_USD_POINT_VALUES
from .converted import cached, hold_cap, write_ply
from .gltf import _Names, sanitize

MAX_SAMPLES = 100_000  # time samples per prim we are willing to key
MAX_TOTAL_SAMPLES = 500_000  # time samples of all prims of one stage together
FOV_SUBKEYS = 16  # fov keys per focal-length sample interval (docs/imports.md)


def _fail(shown: str, where: str, message: str) -> None:
    raise ImportFileError(shown, where, message)


def _trs(m: np.ndarray, shown: str, where: str) -> dict[str, Any]:
    """A column-vector 4x4 matrix -> translate, rotate (quaternion wxyz), scale."""
    from scipy.spatial.transform import Rotation

    if not np.isfinite(m).all():
        _fail(shown, where, "non-finite transform")
    a = m[:3, :3]
    s = np.linalg.norm(a, axis=0)
    if (s < 1e-12).any():
        _fail(shown, where, "a zero scale is not supported")
    r = a / s
    if np.linalg.det(r) < 0:
        _fail(shown, where, "a mirroring (negative scale) transform is not supported")
    if np.abs(r.T @ r - np.eye(3)).max() > 1e-4:
        _fail(shown, where, "a sheared transform is not supported (translate, rotate, scale only)")
    x, y, z, w = Rotation.from_matrix(r).as_quat()
    return {"translate": [float(v) for v in m[:3, 3]], "rotate": {"quaternion": [float(w), float(x), float(y), float(z)]}, "scale": [float(v) for v in s]}


TURN_STEP = 90.0  # degrees: the most a rotate op turns between two keys we write


def _turn_codes(xf: Any, times: list[float]) -> list[float]:
    """The time codes to key: the op samples, plus as many evenly spaced codes inside each
    interval as keep every rotate op's angles (which USD interpolates linearly, so
    0 -> 270 degrees turns 270 the long way) under TURN_STEP apart: slerp between keys
    then follows USD's turn instead of the shortest arc, exactly for one-axis ops."""
    from pxr import Usd, UsdGeom

    rotates = [op for op in xf.GetOrderedXformOps() if str(UsdGeom.XformOp.GetOpTypeToken(op.GetOpType())).startswith("rotate")]
    codes: list[float] = []
    for a, b in zip(times[:-1], times[1:]):
        turn = 0.0
        for op in rotates:
            va, vb = op.Get(Usd.TimeCode(a)), op.Get(Usd.TimeCode(b))
            if va is not None and vb is not None:
                turn = max(turn, float(np.max(np.abs(np.subtract(np.asarray(vb, dtype=np.float64), np.asarray(va, dtype=np.float64))))))
        steps = max(1, min(int(math.ceil(turn / TURN_STEP)), MAX_SAMPLES))
        codes.extend(a + (b - a) * k / steps for k in range(steps))
    return codes + times[-1:]


def _matrix(gf: Any) -> np.ndarray:
    """USD's row-vector Gf.Matrix4d -> our column-vector convention."""
    return np.array(gf, dtype=np.float64).T


class UsdReader:
    """Reads one USD stage into scene records (docs/imports.md)."""

    def __init__(self, path: Path, shown: str, spec: Any, index: int) -> None:
        from pxr import Tf, Usd

        self.path, self.shown, self.spec, self.index = path, shown, spec, index
        try:
            self.stage = Usd.Stage.Open(str(path))
        except Tf.ErrorException as exc:
            _fail(shown, "<stage>", f"cannot open the USD stage: {str(exc).strip().splitlines()[-1]}")
        if self.stage is None:
            _fail(shown, "<stage>", "cannot open the USD stage")
        self.tcps = float(self.stage.GetTimeCodesPerSecond())
        if not math.isfinite(self.tcps) or self.tcps <= 0:
            _fail(shown, "<stage>.timeCodesPerSecond", f"{self.tcps} is not a positive number")
        self.digest = file_digest(path)
        self.names = _Names()
        self.at = "<stage>"  # the prim being read: the location of an unforeseen problem

    def _count_samples(self, n: int, where: str) -> None:
        """The stage's time samples, all prims together, within MAX_TOTAL_SAMPLES (20
        references of 99,999 samples each passed the per-prim limit and ran out of memory)."""
        self.samples_total = getattr(self, "samples_total", 0) + n
        if self.samples_total > MAX_TOTAL_SAMPLES:
            _fail(self.shown, where, f"the stage's prims hold more than {MAX_TOTAL_SAMPLES} time samples together (the limit)")

    def seconds(self, code: float) -> float:
        """Scene seconds of a USD time code (timeCodesPerSecond, plus the import's time_offset)."""
        return code / self.tcps + self.spec.time_offset

    def expand(self) -> Expansion:
        """The records of the import: prims as objects (meshes, xforms), materials, lights and cameras."""
        from pxr import Usd, UsdGeom, UsdLux

        spec = self.spec
        ex = Expansion()
        # every prim's time samples counted before any is read: the budget refuses a stage of
        # 20 references x 99,999 samples at once, not after reading most of them
        total = 0
        for prim in self.stage.Traverse():
            for attr in prim.GetAttributes():
                total += attr.GetNumTimeSamples()
                if total > MAX_TOTAL_SAMPLES:
                    _fail(self.shown, str(prim.GetPath()), f"the stage's prims hold more than {MAX_TOTAL_SAMPLES} time samples together (the limit)")
        # the stage's units and up axis (where authored: USD's own fallback is centimetres,
        # but a stage without the metadata is taken in the shot's metres; docs/imports.md)
        units = float(UsdGeom.GetStageMetersPerUnit(self.stage)) if UsdGeom.StageHasAuthoredMetersPerUnit(self.stage) else 1.0
        if not math.isfinite(units) or units <= 0:
            _fail(self.shown, "<stage>.metersPerUnit", f"{units} is not a positive number")
        up = "z" if UsdGeom.GetStageUpAxis(self.stage) == UsdGeom.Tokens.z else "y"
        frames, root = import_frames(self.names.take, spec, self.index, self.shown, f"{spec.prefix}{sanitize(self.path.stem)}", units, up)
        ex.objects.extend(frames)
        if spec.nodes is not None:
            starts = []
            for name in spec.nodes:
                prim = self.stage.GetPrimAtPath(name) if name.startswith("/") else None
                if prim is None or not prim.IsValid():
                    found = [p for p in self.stage.Traverse() if p.GetName() == name]
                    prim = found[0] if found else None
                if prim is None:
                    raise SpecError("nodes", f"no prim named '{name}' in {self.shown}")
                starts.append(prim)
        else:
            starts = list(self.stage.GetPseudoRoot().GetChildren())
        self.materials: dict[str, str] = {}
        names: dict[str, str] = {}
        for start in starts:
            for prim in Usd.PrimRange(start):
                if not prim.IsA(UsdGeom.Xformable):
                    continue
                path = str(prim.GetPath())
                self.at = path
                parent = prim.GetParent()
                while parent and parent.IsValid() and str(parent.GetPath()) not in names:
                    parent = parent.GetParent()
                xf = UsdGeom.Xformable(prim)
                par = names.get(str(parent.GetPath())) if parent and parent.IsValid() else None
                if xf.GetResetXformStack():
                    par = None
                name = self.names.take(spec.prefix + sanitize(prim.GetName()))
                names[path] = name
                rec: dict[str, Any] = {"name": name, "shape": "empty", "parent": par or root}
                self._transform(xf, rec, path)
                origin = Origin(self.shown, path)
                ex.objects.append((rec, origin))
                if prim.IsA(UsdGeom.Mesh):
                    self._mesh(prim, rec, path, ex)
                elif prim.IsA(UsdGeom.Camera):
                    ex.cameras.append((prim.GetName(), self._camera(prim, name, path), Origin(self.shown, path)))
                elif prim.HasAPI(UsdLux.LightAPI) or prim.IsA(UsdLux.BoundableLightBase) or prim.IsA(UsdLux.NonboundableLightBase):
                    self._light(prim, name, path, ex)
        for mat_path, mat_name in self.materials.items():
            ex.materials.append((self._material(mat_path, mat_name), Origin(self.shown, mat_path)))
        return ex

    # --- transforms ---------------------------------------------------------------------

    def _transform(self, xf: Any, rec: dict[str, Any], where: str) -> None:
        from pxr import Usd

        times = sorted(xf.GetTimeSamples())
        if len(times) > MAX_SAMPLES:
            _fail(self.shown, where, f"{len(times)} transform time samples; the limit is {MAX_SAMPLES}")
        self._count_samples(len(times), where)
        if len(times) <= 1:
            code = Usd.TimeCode(times[0]) if times else Usd.TimeCode.Default()
            rec["transform"] = _trs(_matrix(xf.GetLocalTransformation(code)), self.shown, f"{where}.xformOp")
            return
        keys: dict[str, list[dict[str, Any]]] = {"translate": [], "rotate": [], "scale": []}
        for code in _turn_codes(xf, times):
            trs = _trs(_matrix(xf.GetLocalTransformation(Usd.TimeCode(code))), self.shown, f"{where}.xformOp (time {code})")
            t = self.seconds(code)
            keys["translate"].append({"time": t, "value": trs["translate"]})
            keys["rotate"].append({"time": t, "quaternion": trs["rotate"]["quaternion"]})
            keys["scale"].append({"time": t, "value": trs["scale"]})
        rec["motion"] = {"type": "keyframes", "time_unit": "seconds", "interpolation": "linear", "extrapolation": "hold", "channels": {k: {"keys": v} for k, v in keys.items()}}

    # --- meshes and materials -----------------------------------------------------------

    def _mesh(self, prim: Any, rec: dict[str, Any], where: str, ex: Expansion) -> None:
        from pxr import Usd, UsdGeom, UsdShade

        mesh = UsdGeom.Mesh(prim)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
        points_attr = mesh.GetPointsAttr()
        times = sorted(points_attr.GetTimeSamples())
        first = Usd.TimeCode(times[0]) if times else Usd.TimeCode.Default()
        points = np.asarray(points_attr.Get(first) or [], dtype=np.float64).reshape(-1, 3)
        if counts.sum() != len(indices) or (counts < 3).any():
            _fail(self.shown, f"{where}.faceVertexCounts", f"face vertex counts (sum {int(counts.sum())}) do not match {len(indices)} face vertex indices")
        if len(indices) and (indices.min() < 0 or indices.max() >= len(points)):
            _fail(self.shown, f"{where}.faceVertexIndices", f"index {int(indices.max())} is out of range for {len(points)} points")
        if not np.isfinite(points).all():
            _fail(self.shown, f"{where}.points", "non-finite point")
        # texture coordinates (primvars:st): per point, or per face corner (then every
        # corner becomes its own vertex, and the faces index corners); USD's t runs up
        corner_point = None
        uvs = None
        st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
        if st and st.HasValue():
            values = np.asarray(st.ComputeFlattened(first) or [], dtype=np.float64).reshape(-1, 2)
            interp = st.GetInterpolation()
            if interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) and len(values) == len(points):
                uvs = values
            elif interp == UsdGeom.Tokens.faceVarying and len(values) == len(indices):
                uvs, corner_point = values, indices
            if uvs is not None:
                if not np.isfinite(uvs).all():
                    _fail(self.shown, f"{where}.primvars:st", "non-finite texture coordinate")
                uvs = np.column_stack((uvs[:, 0], 1.0 - uvs[:, 1]))
        # fan-triangulate each polygon: (v0, v_i, v_i+1), over points or over corners
        corners = np.arange(len(indices)) if corner_point is not None else indices
        starts = np.repeat(np.concatenate(([0], np.cumsum(counts)[:-1])), counts - 2)
        step = np.arange(len(starts)) - np.repeat(np.concatenate(([0], np.cumsum(counts - 2)[:-1])), counts - 2) + 1
        faces = np.stack((corners[starts], corners[starts + step], corners[starts + step + 1]), axis=1).reshape(-1, 3)
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            faces = faces[:, ::-1]
        expand = (lambda p: p[corner_point]) if corner_point is not None else (lambda p: p)
        rec["shape"] = "mesh"
        rec["file"] = str(cached(sanitize(prim.GetName()), f"{self.digest}|usd-mesh|{where}|{times[0] if times else 'default'}", ".ply", lambda tmp: write_ply(tmp, expand(points), faces, None, uvs)))
        if len(times) > 1:
            # each sample of deforming points is a mesh file and a blend-shape key: bounded in
            # samples and in values read (99,999 samples hung the import)
            if len(times) > MAX_USD_POINT_SAMPLES:
                _fail(self.shown, f"{where}.points", f"{len(times)} time samples of deforming points; the limit is {MAX_USD_POINT_SAMPLES} "
                                                    "(bake dense motion to a file: `motion render --motion`)")
            if len(times) * len(points) * 3 > MAX_USD_POINT_VALUES:
                _fail(self.shown, f"{where}.points", f"{len(times)} time samples of {len(points)} points are {len(times) * len(points) * 3} values; the limit is {MAX_USD_POINT_VALUES}")
            self._count_samples(len(times), f"{where}.points")
            keys = []
            for code in times:
                pts = np.asarray(points_attr.Get(Usd.TimeCode(code)), dtype=np.float64).reshape(-1, 3)
                if pts.shape != points.shape or not np.isfinite(pts).all():
                    _fail(self.shown, f"{where}.points (time {code})", f"{len(pts)} points; expected {len(points)} finite (the same topology at every sample)")
                file = cached(sanitize(prim.GetName()), f"{self.digest}|usd-points|{where}|{code}", ".ply", lambda tmp, pts=pts: write_ply(tmp, expand(pts), faces), hold_cap=False)
                keys.append({"time": self.seconds(code), "file": str(file)})
            hold_cap()  # once for the run of samples (each hold lists the whole cache: quadratic in samples)
            rec["deform"] = {"type": "blend-shapes", "time_unit": "seconds", "interpolation": "linear", "keys": keys}
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if material:
            mpath = str(material.GetPath())
            if mpath not in self.materials:
                self.materials[mpath] = self.names.take(self.spec.prefix + sanitize(material.GetPrim().GetName()))
            rec["material"] = self.materials[mpath]
            emission = self._surface_input(mpath, "emissiveColor")
            glow = self._texture(mpath, "emissiveColor")
            if glow is not None:
                glow.pop("output")
                rec["emission"] = {"radiance": glow}
            elif emission is not None and any(v > 0 for v in emission):
                rec["emission"] = {"radiance": emission}

    def _shader(self, mat_path: str) -> Any:
        from pxr import UsdShade

        material = UsdShade.Material(self.stage.GetPrimAtPath(mat_path))
        surface = material.ComputeSurfaceSource()[0]
        if surface and surface.GetIdAttr().Get() == "UsdPreviewSurface":
            return surface
        return None

    def _surface_input(self, mat_path: str, name: str) -> list[float] | float | None:
        shader = self._shader(mat_path)
        if shader is None:
            return None
        inp = shader.GetInput(name)
        if not inp:
            return None
        value = inp.Get()
        if value is None:
            return None
        if hasattr(value, "__len__"):
            return [float(v) for v in value]
        return float(value)

    def _texture(self, mat_path: str, name: str) -> dict[str, Any] | None:
        """A UsdUVTexture connected to the surface input `name`, as a texture record."""
        from pxr import UsdShade

        shader = self._shader(mat_path)
        inp = shader.GetInput(name) if shader is not None else None
        if not inp:
            return None
        sources = inp.GetConnectedSources()[0]
        if not sources:
            return None
        tex = UsdShade.Shader(sources[0].source.GetPrim())
        if tex.GetIdAttr().Get() != "UsdUVTexture" or not tex.GetInput("file"):
            return None
        asset = tex.GetInput("file").Get()
        where = f"{tex.GetPath()}.inputs:file"
        if asset is None or not asset.resolvedPath:
            _fail(self.shown, where, f"texture file not found: {asset.path if asset is not None else '(none)'}")
        space = tex.GetInput("sourceColorSpace").Get() if tex.GetInput("sourceColorSpace") else None
        return {"file": asset.resolvedPath, "raw": space == "raw", "output": str(sources[0].sourceName)}

    def _grey_texture(self, mat_path: str, name: str, threshold: float = 0.0) -> dict[str, Any] | None:
        """A UsdUVTexture's one channel (the output connected to input `name`: r, g, b or a)
        as a raw grey texture in the asset cache, cut at `threshold` (1 at or above, else 0)
        when it is positive; the file itself where it is read whole (rgb, no cut)."""
        texture = self._texture(mat_path, name)
        if texture is None:
            return None
        output = texture.pop("output")
        if output not in ("r", "g", "b", "a") and threshold <= 0:
            return {**texture, "raw": True}
        channel = "rgba".index(output) if output in ("r", "g", "b", "a") else 0
        source = Path(texture["file"])

        def write(tmp: Path) -> None:
            from PIL import Image, UnidentifiedImageError

            try:
                with Image.open(source) as im:
                    arr = np.asarray(im.convert("RGBA"), dtype=np.float64)[:, :, channel] / 255
            except (UnidentifiedImageError, OSError) as exc:
                _fail(self.shown, f"{mat_path}.inputs:{name}", f"cannot decode the texture {source.name}: {exc}")
            if threshold > 0:
                arr = (arr >= threshold).astype(np.float64)
            Image.fromarray(np.rint(arr * 255).astype(np.uint8)).save(tmp, format="PNG")

        key = f"{file_digest(source)}|channel{channel}|cut{threshold}"
        return {"file": str(cached(f"{source.stem}-{output}", key, ".png", write)), "raw": True}

    def _material(self, mat_path: str, name: str) -> dict[str, Any]:
        """UsdPreviewSurface -> principled: diffuseColor, metallic, roughness (constants or
        UsdUVTextures), clearcoat; `normal` (a texture) -> normal_map; `opacity` (constant or
        texture) -> opacity, cut at a positive opacityThreshold (constants only);
        emissiveColor (constant or texture) -> the object's emission (`_mesh`). A texture read
        through one channel (outputs:r/g/b/a) becomes that channel as a grey texture."""
        rec: dict[str, Any] = {"name": name, "type": "principled"}
        if self._shader(mat_path) is None:
            return {"name": name, "type": "diffuse"}
        color = self._surface_input(mat_path, "diffuseColor")
        rec["color"] = [min(max(c, 0.0), 1e6) for c in color] if isinstance(color, list) else 0.18
        texture = self._texture(mat_path, "diffuseColor")
        if texture is not None:
            texture.pop("output")
            rec["color"] = texture
        for key, src in (("metallic", "metallic"), ("roughness", "roughness"), ("clearcoat", "clearcoat")):
            v = self._surface_input(mat_path, src)
            if isinstance(v, float):
                rec[key] = min(max(v, 0.0), 1.0)
            texture = self._grey_texture(mat_path, src) if key != "clearcoat" else None
            if texture is not None:
                rec[key] = texture
        normal = self._texture(mat_path, "normal")
        if normal is not None:
            normal.pop("output")
            rec["normal_map"] = {**normal, "raw": True}
        opacity = self._surface_input(mat_path, "opacity")
        threshold = self._surface_input(mat_path, "opacityThreshold")
        cut = float(threshold) if isinstance(threshold, float) and threshold > 0 else 0.0
        mask = self._grey_texture(mat_path, "opacity", cut)
        if mask is not None:
            rec["opacity"] = mask
        elif isinstance(opacity, float) and opacity < 1.0:
            rec["opacity"] = (1.0 if opacity >= cut else 0.0) if cut else min(max(opacity, 0.0), 1.0)
        return rec

    # --- cameras and lights -------------------------------------------------------------

    def _camera(self, prim: Any, node: str, where: str) -> dict[str, Any]:
        from pxr import Usd, UsdGeom

        cam = UsdGeom.Camera(prim)
        # USD cameras look along -Z with +Y up; ours along +Z: turn 180 degrees about Y
        rec: dict[str, Any] = {"parent": node, "transform": {"rotate": {"axis": [0.0, 1.0, 0.0], "angle": 180.0}}}
        clip = cam.GetClippingRangeAttr().Get()
        if clip is not None:
            rec["near"], rec["far"] = float(clip[0]), float(clip[1])

        def fov(code: Any) -> float:
            focal = float(cam.GetFocalLengthAttr().Get(code))
            aperture = float(cam.GetHorizontalApertureAttr().Get(code))
            if not (focal > 0 and aperture > 0):
                _fail(self.shown, f"{where}.focalLength", f"focal length {focal} and horizontal aperture {aperture} must be positive")
            return math.degrees(2 * math.atan(aperture / (2 * focal)))

        if cam.GetProjectionAttr().Get() == UsdGeom.Tokens.orthographic:
            # apertures are in tenths of a scene unit (USD's convention)
            rec.update({"type": "orthographic", "ortho_width": float(cam.GetHorizontalApertureAttr().Get()) / 10.0})
            return rec
        rec.update({"type": "perspective", "fov_axis": "x", "fov": fov(Usd.TimeCode.Default())})
        times = sorted(set(cam.GetFocalLengthAttr().GetTimeSamples()) | set(cam.GetHorizontalApertureAttr().GetTimeSamples()))
        if times:
            rec["fov"] = fov(Usd.TimeCode(times[0]))
        if len(times) > 1:
            # USD lerps the focal length; the field of view is not linear in it: key the
            # samples and FOV_SUBKEYS points between them (USD's own interpolated values)
            codes = [float(c) for a, b in zip(times[:-1], times[1:]) for c in np.linspace(a, b, FOV_SUBKEYS + 1)[:-1]] + [times[-1]]
            keys = [{"time": self.seconds(c), "value": fov(Usd.TimeCode(c))} for c in codes]
            rec["motion"] = {"type": "keyframes", "time_unit": "seconds", "interpolation": "catmull-rom", "channels": {"fov": {"keys": keys}}}
        return rec

    def _light(self, prim: Any, node: str, where: str, ex: Expansion) -> None:
        from pxr import UsdLux

        light = UsdLux.LightAPI(prim)
        intensity = float(light.GetIntensityAttr().Get() or 0.0) * 2.0 ** float(light.GetExposureAttr().Get() or 0.0)
        color = np.asarray(light.GetColorAttr().Get() or (1.0, 1.0, 1.0), dtype=np.float64)
        power = [float(v) for v in color * intensity * self.spec.light_scale]
        if not all(math.isfinite(v) and v >= 0 for v in power):
            _fail(self.shown, f"{where}.inputs:intensity", "intensity and colour must be finite and non-negative")
        name = self.names.take(f"{node}.light")
        origin = Origin(self.shown, where)
        if prim.IsA(UsdLux.DistantLight):
            ex.lights.append(({"name": name, "type": "directional", "parent": node, "direction": [0.0, 0.0, -1.0], "irradiance": power}, origin))
        elif prim.IsA(UsdLux.SphereLight):
            ex.lights.append(({"name": name, "type": "point", "parent": node, "position": [0.0, 0.0, 0.0], "intensity": power}, origin))
        elif prim.IsA(UsdLux.DomeLight):
            file = UsdLux.DomeLight(prim).GetTextureFileAttr().Get()
            if file and file.resolvedPath:
                ex.lights.append(({"name": name, "type": "envmap", "file": file.resolvedPath, "scale": intensity * self.spec.light_scale}, origin))
            else:
                ex.lights.append(({"name": name, "type": "constant", "radiance": power}, origin))
        elif prim.IsA(UsdLux.RectLight):
            rect = UsdLux.RectLight(prim)
            w, h = float(rect.GetWidthAttr().Get()), float(rect.GetHeightAttr().Get())
            # an emitting rectangle; UsdLux rect lights emit along -Z, our rectangles along +Z
            ex.objects.append(({"name": name, "shape": "rectangle", "parent": node, "width": w, "height": h, "transform": {"rotate": {"axis": [0.0, 1.0, 0.0], "angle": 180.0}}, "emission": {"radiance": power}}, origin))
        else:
            _fail(self.shown, where, f"light type {prim.GetTypeName()} is not supported (distant, sphere, rect, dome)")


def check_layers(path: Path, root: Path, shown: str) -> None:
    """Every layer the stage would load (sublayers, references, payloads, recursively),
    checked before USD opens any: inside the scene's folder `root`, a regular file (a FIFO
    as a sublayer hung forever, /dev/zero was read), within the size limit, and no layer
    within its own chain (a layer that sublayers itself). ImportFileError naming the layer."""
    import stat as stat_mod

    from pxr import Sdf, Tf

    from ...write_policy import confined

    base = root.resolve()
    seen: set[Path] = set()
    stack: list[tuple[Path, tuple[Path, ...]]] = [(path, ())]
    while stack:
        layer_path, chain = stack.pop()
        real = layer_path.resolve()
        named = layer_path.name if not chain else f"{chain[-1].name} -> {layer_path}"
        if real in chain:
            _fail(shown, "<layers>", f"layer cycle: {' -> '.join(p.name for p in (*chain, real))}")
        if real in seen:
            continue
        seen.add(real)
        if len(seen) > MAX_LAYERS:
            _fail(shown, "<layers>", f"more than {MAX_LAYERS} layers")
        if not confined(base, real):
            _fail(shown, "<layers>", f"layer {named} is outside the scene's folder {base}")
        try:
            st = os.stat(real)
        except OSError as exc:
            _fail(shown, "<layers>", f"layer {named}: {exc.strerror}")
        if not stat_mod.S_ISREG(st.st_mode):
            _fail(shown, "<layers>", f"layer {named} is not a regular file (a device, pipe or folder)")
        if st.st_size > MAX_LAYER_BYTES:
            _fail(shown, "<layers>", f"layer {named} is {st.st_size} bytes; the limit is {MAX_LAYER_BYTES}")
        file_digest(real)  # the records depend on its bytes (imports/memo.py keeps them by these digests)
        try:
            layer = Sdf.Layer.FindOrOpen(str(real))
        except Tf.ErrorException as exc:
            _fail(shown, "<stage>", f"cannot open the USD stage: layer {named}: {str(exc).strip().splitlines()[-1]}")
        if layer is None:
            _fail(shown, "<layers>", f"layer {named} is not a readable USD layer")
        for dep in layer.GetCompositionAssetDependencies():
            if not dep:
                continue
            target = Path(dep) if os.path.isabs(dep) else real.parent / dep
            stack.append((target, (*chain, real)))


MAX_LAYERS = 1000  # layers one stage may bring in


def read_usd(path: Path, shown: str, spec: Any, index: int, root: Path | None = None) -> Expansion:
    """The records of one USD import; ImportFileError (file and prim) otherwise. Its
    layers are checked first (`check_layers`, confined to `root`, the scene's folder)."""
    try:
        from pxr import Usd  # noqa: F401
    except ImportError as exc:  # pragma: no cover - usd-core is a dependency
        raise ImportFileError(shown, "<stage>", f"usd-core is not installed: {exc}") from None
    if spec.animation not in (None, -1):
        raise SpecError("animation", "USD stages have one timeline; `animation` applies to glTF files")
    from pxr import Tf

    reader = None
    try:
        check_layers(path, root if root is not None else path.parent, shown)
        reader = UsdReader(path, shown, spec, index)
        return reader.expand()
    except (SpecError, ImportFileError):
        raise
    except (Tf.ErrorException, TypeError, AttributeError, ValueError, IndexError, OverflowError) as exc:
        where = reader.at if reader is not None else "<stage>"
        raise ImportFileError(shown, where, f"cannot read: {type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else ''}") from None
