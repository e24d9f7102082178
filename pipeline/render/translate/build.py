"""Scene records -> Mitsuba scene dictionaries, through one registry per concept keyed by
`type` (materials, lights) or `shape` (objects), as pbrt's factories do.

Poses come from the motion stage (`Pose`: translation, wxyz quaternion, scale); this module
only turns records and poses into dictionaries; it loads nothing itself.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

import numpy as np

from ...geometry import scale_matrix, shape_geometry
from ...motion.pose import quat_normalize, quat_to_matrix
from ...scene.loader import LoadedScene
from ...scene.schema import (
    Camera,
    Conductor,
    Dielectric,
    Diffuse,
    Plastic,
    Principled,
    ThinDielectric,
)
from ...scene.types import Texture

Dict = dict[str, Any]


# --- small math ---------------------------------------------------------------------------




def mitsuba_id(name: str) -> str:
    """A scene name as a key of a Mitsuba scene dictionary. Mitsuba reserves '.' as its
    object-path delimiter (an object 'a.b', or a glTF node named like its file 'walker.glb',
    failed every frame): such a name becomes 'a_b_<6 hex of the name>', unique and stable."""
    if "." not in name:
        return name
    import hashlib

    return f"{name.replace('.', '_')}_{hashlib.sha1(name.encode()).hexdigest()[:6]}"


def trs_matrix(translation: Iterable[float], rotation: Iterable[float], scale: Iterable[float] = (1, 1, 1)) -> np.ndarray:
    """world_from_object = T * R * S as a 4x4 matrix."""
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(quat_normalize(np.asarray(rotation, float))) * np.asarray(scale, float)[None, :]
    m[:3, 3] = np.asarray(translation, float)
    return m


def _mi() -> Any:
    import mitsuba as mi

    return mi


def _xf(matrix: np.ndarray) -> Any:
    return _mi().ScalarTransform4f(np.asarray(matrix, dtype=np.float64).tolist())


# --- colours and textures -----------------------------------------------------------------


def color(value: Any, loaded: LoadedScene, raw: bool = False) -> Any:
    """A colour field: grey float, RGB triple, or a bitmap texture (`raw`: data, never
    sRGB-decoded, whatever the texture says: normal and bump maps)."""
    if isinstance(value, Texture):
        tile = value.tile if isinstance(value.tile, tuple) else (value.tile, value.tile)
        return {
            "type": "bitmap",
            "filename": str(loaded.asset(value.file)),
            "filter_type": value.filter,
            "wrap_mode": value.wrap,
            "raw": value.raw or raw,
            "to_uv": _mi().ScalarTransform4f().scale([tile[0], tile[1], 1.0]),
        }
    if isinstance(value, (tuple, list)):
        return {"type": "rgb", "value": [float(v) for v in value]}
    return float(value)


def spectrum(value: Any) -> Any:
    """A spectrum field (emission, tint, light colour): grey float or RGB triple."""
    if isinstance(value, (tuple, list)):
        return {"type": "rgb", "value": [float(v) for v in value]}
    return float(value)


# --- materials ----------------------------------------------------------------------------

MaterialBuilder = Callable[[Any, LoadedScene], Dict]
MATERIALS: dict[str, MaterialBuilder] = {}


def _material(kind: str) -> Callable[[MaterialBuilder], MaterialBuilder]:
    def register(fn: MaterialBuilder) -> MaterialBuilder:
        MATERIALS[kind] = fn
        return fn

    return register


# Roughness in our files is perceptual; GGX alpha = roughness^2 (as in Disney/principled).
def _alpha(roughness: float) -> float:
    return max(float(roughness) ** 2, 1e-4)


@_material("diffuse")
def _diffuse(m: Diffuse, loaded: LoadedScene) -> Dict:
    return {"type": "diffuse", "reflectance": color(m.color, loaded)}


def _smooth_or_rough(plugin: str, roughness: Any, loaded: LoadedScene | None = None, **params: Any) -> Dict:
    """Mitsuba's smooth `plugin`, or its GGX `rough<plugin>` when roughness > 0; a
    roughness texture becomes a cached alpha texture (its square, `assets.alpha_texture`)."""
    if isinstance(roughness, Texture) and loaded is not None:
        from .assets import alpha_texture

        alpha = {**color(roughness, loaded, raw=True), "filename": str(alpha_texture(loaded.asset(roughness.file), roughness.raw))}
        return {"type": f"rough{plugin}", "alpha": alpha, "distribution": "ggx", **params}
    if roughness == 0:
        return {"type": plugin, **params}
    return {"type": f"rough{plugin}", "alpha": _alpha(roughness), "distribution": "ggx", **params}


@_material("plastic")
def _plastic(m: Plastic, loaded: LoadedScene) -> Dict:
    return _smooth_or_rough("plastic", m.roughness, diffuse_reflectance=color(m.color, loaded), int_ior=m.ior)


@_material("conductor")
def _conductor(m: Conductor, loaded: LoadedScene) -> Dict:
    return _smooth_or_rough("conductor", m.roughness, loaded, material=m.preset, specular_reflectance=color(m.tint, loaded))


@_material("dielectric")
def _dielectric(m: Dielectric, loaded: LoadedScene) -> Dict:
    return _smooth_or_rough("dielectric", m.roughness, loaded, int_ior=m.ior, specular_transmittance=color(m.tint, loaded))


@_material("thindielectric")
def _thindielectric(m: ThinDielectric, loaded: LoadedScene) -> Dict:
    return {"type": "thindielectric", "int_ior": m.ior, "specular_transmittance": color(m.tint, loaded)}


@_material("principled")
def _principled(m: Principled, loaded: LoadedScene) -> Dict:
    return {
        "type": "principled",
        "base_color": color(m.color, loaded),
        "metallic": color(m.metallic, loaded),
        "roughness": color(m.roughness, loaded),
        "specular": m.specular,
        "clearcoat": color(m.clearcoat, loaded, raw=True),
    }


def material_dict(m: Any, loaded: LoadedScene) -> Dict:
    """The Mitsuba BSDF of a scene material, wrapped inside out: its normal or bump map,
    two-sided when asked, its opacity mask outermost."""
    d = MATERIALS[m.type](m, loaded)
    if m.normal_map is not None:
        d = {"type": "normalmap", "normalmap": color(m.normal_map, loaded, raw=True), "bsdf": d}
    elif m.bump is not None:
        d = {"type": "bumpmap", "texture": color(m.bump, loaded, raw=True), "scale": float(m.bump_scale), "bsdf": d}
    if m.two_sided:
        d = {"type": "twosided", "material": d}
    if isinstance(m.opacity, Texture) or m.opacity != 1.0:
        d = {"type": "mask", "opacity": color(m.opacity, loaded, raw=True), "bsdf": d}
    return d


def emitter_dict(emission: Any, loaded: LoadedScene) -> Dict:
    """The area emitter of an object's `emission:` (a texture: RGB over the surface's uv)."""
    return {"type": "area", "radiance": color(emission.radiance, loaded)}


DEFAULT_MATERIAL: Dict = {"type": "diffuse", "reflectance": 0.5}


def object_material(obj: Any, materials: dict[str, Any]) -> Any:
    """The material an object wears: its named one of `materials`, else the default."""
    return materials.get(obj.material, DEFAULT_MATERIAL) if obj.material else DEFAULT_MATERIAL


def dressed(d: Dict, obj: Any, loaded: LoadedScene, materials: dict[str, Any]) -> Dict:
    """A shape dictionary `d` wearing its object's material and, if it glows, its area
    emitter (every shape of an object, a particle system's holder and its particles)."""
    d["bsdf"] = object_material(obj, materials)
    if obj.emission is not None:
        d["emitter"] = emitter_dict(obj.emission, loaded)
    return d


# --- shapes -------------------------------------------------------------------------------

# Every shape's Mitsuba primitives come from its geometry entry (pipeline/geometry.py), in
# OBJECT space (to_world = the object's geometry-from-unit-primitive transform); the caller
# pre-multiplies the pose. A mesh file is drawn from its (converted) file; particles are
# geometry built per frame by the renderer.


def shape_primitives(obj: Any, loaded: LoadedScene) -> list[tuple[Dict, np.ndarray]]:
    """(Mitsuba shape dictionary, object_from_prim 4x4) of each primitive of one object."""
    entry = shape_geometry(obj.shape)
    if entry.file_mesh:
        from .assets import mesh_file

        path = mesh_file(loaded.asset(obj.file))
        kind = "ply" if path.suffix.lower() == ".ply" else "obj"
        return [({"type": kind, "filename": str(path), "face_normals": obj.face_normals}, np.eye(4))]
    return [({"type": p.plugin}, p.object_from_prim) for p in entry.primitives(obj)]  # type: ignore[misc]


def object_shapes(obj: Any, loaded: LoadedScene, world_from_object: np.ndarray, materials: dict[str, Dict]) -> list[Dict]:
    """The Mitsuba shape dictionaries of one object at one pose."""
    out = []
    for d, object_from_prim in shape_primitives(obj, loaded):
        d = dict(d)
        d["to_world"] = _xf(world_from_object @ object_from_prim)
        out.append(dressed(d, obj, loaded, materials))
    return out


# --- lights -------------------------------------------------------------------------------


def light_dict(light: Any, loaded: LoadedScene, world_from_light: np.ndarray | None, scalars: dict[str, Any]) -> Dict:
    """One light at one time, placed by its frame exactly once: the light record's own
    `emitter` (scene/schema.py LIGHT_TYPES), with its matrix and colour in Mitsuba's terms.

    `world_from_light` is the light's pose from the motion stage (None = identity): its
    origin is the light's position and its +Z axis the direction it shines (spot axis,
    directional travel direction), as in Mitsuba's emitters; the record's `position`,
    `look_at` and `direction` are already folded into it (motion/evaluate.py). `scalars`
    holds the light's emission channel at that time (`light.channel`), from its keys; the
    record's own value otherwise. `loaded` resolves the light's files.
    """
    m = np.eye(4) if world_from_light is None else np.asarray(world_from_light, dtype=float)
    if light.rigid_frame:
        m = _rigid(m)
    value = scalars.get(light.channel)
    value = light.emission if value is None else value
    value = spectrum(value) if light.channel_size == 3 else float(value)

    d = dict(light.emitter(value, m, lambda name: str(loaded.asset(name))))
    if "to_world" in d:
        d["to_world"] = _xf(d["to_world"])
    return d


def unit_light_dict(light: Any, loaded: LoadedScene) -> Dict:
    """A moving light that is posed per path (`posed_per_path`) in its own frame (at the
    origin, shining along +Z) with unit emission: the integrator poses it per path and
    scales its colour."""
    return light_dict(light, loaded, None, {light.channel: 1.0})


def _rigid(m: np.ndarray) -> np.ndarray:
    """The rotation and translation of a pose matrix, without its scale (a light's frame
    is rigid: a scaled parent moves it but does not stretch its beam)."""
    r = m[:3, :3]
    norms = np.linalg.norm(r, axis=0)
    out = np.eye(4)
    out[:3, :3] = r / np.where(norms > 0, norms, 1.0)
    out[:3, 3] = m[:3, 3]
    return out


# --- camera -------------------------------------------------------------------------------


def sensor_dict(
    camera: Camera,
    world_from_camera: np.ndarray,
    fov: float,
    resolution: tuple[int, int],
    spp: int,
    rfilter: str,
    shutter: tuple[float, float] = (0.0, 0.0),
    ortho_width: float | None = None,
    sampler: str = "independent",
    aovs: bool = False,
) -> Dict:
    """A sensor at one pose. Mitsuba's camera looks along local +Z with +Y up."""
    film: Dict = {
        "type": "hdrfilm",
        "width": int(resolution[0]),
        "height": int(resolution[1]),
        "rfilter": {"type": rfilter},
        "pixel_format": "rgba",
        "sample_border": False,
    }
    d: Dict = {
        "type": camera.type,
        "near_clip": camera.near,
        "far_clip": camera.far,
        "film": film,
        "sampler": {"type": sampler, "sample_count": int(spp)},
        "shutter_open": float(shutter[0]),
        "shutter_close": float(shutter[1]),
    }
    if camera.type == "perspective":
        d["fov"] = float(fov)
        d["fov_axis"] = camera.fov_axis
        d["to_world"] = _xf(world_from_camera)
    else:
        # Mitsuba's orthographic camera sees camera-space x in [-1, 1]: scale by width / 2.
        half = float(ortho_width if ortho_width is not None else camera.ortho_width) / 2
        d["to_world"] = _xf(world_from_camera @ scale_matrix(half, half, 1.0))
    return d


def look_at_matrix(position: Iterable[float], target: Iterable[float], up: Iterable[float]) -> np.ndarray:
    """Mitsuba's look_at: columns (left, up', dir, origin)."""
    o = np.asarray(position, float)
    d = np.asarray(target, float) - o
    d /= np.linalg.norm(d)
    left = np.cross(np.asarray(up, float), d)
    n = np.linalg.norm(left)
    if n < 1e-9:  # up parallel to the view direction: pick another up
        left = np.cross([0.0, 0.0, 1.0] if abs(d[1]) > 0.9 else [0.0, 1.0, 0.0], d)
        n = np.linalg.norm(left)
    left /= n
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m
