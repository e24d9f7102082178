"""Scene format v1: typed, immutable records parsed from YAML (docs/scene-format.md).

Parse first, build later: these records describe the shot; the render stage turns them
into Mitsuba dictionaries through a registry keyed by `type`, and the motion stage
evaluates their `motion` blocks.
"""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

from fractions import Fraction
from typing import Annotated, Any, ClassVar, Literal, Union

from pydantic import Field, field_validator, model_validator

from ..deliverables import NAMES as DELIVER_NAMES
from ..timeline import Timeline, parse_fps
from .dynamics_schema import DynamicsSettings, ParticleEmitter
from .imports.spec import ImportSpec
from .lights import (  # the light records live in lights.py; these names stay importable from here
    Aim,
    LIGHT_TYPES,
    ConstantLight,
    DirectionalLight,
    EnvmapLight,
    Light,
    PointLight,
    ProjectorLight,
    SpotLight,
)
from .motion_schema import Deformation, IKConstraint, MotionBlock, StaticMotion
from .types import (
    Color,
    FiniteFloat,
    Model,
    Name,
    NonNegative,
    Positive,
    Size3,
    Texture,
    Transform,
    Vec3,
)


# --- timeline -----------------------------------------------------------------------------


class TimelineSpec(Model):
    """Frame rate (an integer, a decimal or a ratio such as 30000/1001) and frame range."""

    fps: Union[int, float, str] = 24
    first: int = 0
    last: int = 0

    @field_validator("fps")
    @classmethod
    def _fps(cls, value: int | float | str) -> str:
        return str(parse_fps(value))

    @model_validator(mode="after")
    def _range(self) -> "TimelineSpec":
        if self.last < self.first:
            raise ValueError(f"frame range is reversed: first {self.first} > last {self.last}")
        return self

    @property
    def rate(self) -> Fraction:
        """The frame rate, exact."""
        return parse_fps(self.fps)

    def timeline(self) -> Timeline:
        """The Timeline of this block (frame <-> seconds, shutter intervals)."""
        return Timeline(fps=self.rate, first=self.first, last=self.last)


# --- camera -------------------------------------------------------------------------------


class Shutter(Model):
    """Shutter angle in degrees (0, 360]: open for angle/360 of the frame."""

    angle: Annotated[float, Field(gt=0, le=360)] = 180.0
    position: Literal["start", "center", "end"] = "center"


class Camera(Model):
    """The shot's camera: placed by position/look_at/up or by a transform, with a field of
    view (degrees, along fov_axis) or an orthographic width, clip planes and a shutter."""

    type: Literal["perspective", "orthographic"] = "perspective"
    position: Vec3 | None = None
    look_at: Aim | None = None
    up: Vec3 = (0.0, 1.0, 0.0)
    transform: Transform | None = None
    fov: Annotated[float, Field(gt=0, lt=180)] = 40.0
    fov_axis: Literal["x", "y", "diagonal", "smaller", "larger"] = "x"
    ortho_width: Positive = 2.0  # metres across the image's x axis (orthographic)
    near: Positive = 0.01
    far: Positive = 10000.0
    shutter: Shutter = Shutter.default()
    parent: Name | None = None
    motion: MotionBlock = StaticMotion.default()

    @model_validator(mode="after")
    def _placement(self) -> "Camera":
        if self.transform is not None and (self.position is not None or self.look_at is not None):
            raise ValueError("give either position/look_at or transform, not both")
        if (self.position is None) != (self.look_at is None):
            raise ValueError("position and look_at go together")
        if self.position is not None and self.look_at is not None and self.position == self.look_at:
            raise ValueError("look_at must differ from position")
        if self.near >= self.far:
            raise ValueError(f"near ({self.near}) must be less than far ({self.far})")
        return self


# --- materials ----------------------------------------------------------------------------

ColorOrTexture = Union[Color, Texture]


class _Material(Model):
    """What every material may carry besides its BSDF: `two_sided` (both faces shade
    alike), a tangent-space `normal_map` (raw RGB, Mitsuba `normalmap`) or a `bump` height
    map (grey, `bump_scale`, Mitsuba `bumpmap`), and `opacity` (a cut-out mask: a grey
    value or texture, Mitsuba `mask`)."""

    name: Name
    two_sided: bool = False
    normal_map: Texture | None = None
    bump: Texture | None = None
    bump_scale: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1.0
    opacity: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 1.0

    @model_validator(mode="after")
    def _one_perturbation(self) -> "_Material":
        if self.normal_map is not None and self.bump is not None:
            raise ValueError("a material takes a normal_map or a bump map, not both")
        return self


class Diffuse(_Material):
    """Lambertian reflection of `color` (a grey, an RGB triple or a texture)."""

    type: Literal["diffuse"]
    color: ColorOrTexture = 0.5


class Plastic(_Material):
    """A diffuse base under a smooth or rough dielectric coating of index `ior`."""

    type: Literal["plastic"]
    color: ColorOrTexture = 0.5
    roughness: Annotated[float, Field(ge=0, le=1)] = 0.0  # 0: smooth coating
    ior: Annotated[float, Field(gt=1, le=4)] = 1.49


# Measured metals Mitsuba ships (data/ior); `none` is a perfect mirror.
ConductorPreset = Literal["Ag", "Al", "AlAs", "AlAs_palik", "AlSb", "AlSb_palik", "Au", "Be", "Be_palik", "Cr", "CsI", "CsI_palik", "Cu", "Cu2O", "Cu2O_palik", "CuO", "CuO_palik", "Cu_palik", "Hg", "HgTe", "HgTe_palik", "Hg_palik", "Ir", "Ir_palik", "K", "K_palik", "Li", "Li_palik", "MgO", "MgO_palik", "Mo", "Mo_palik", "Na_palik", "Nb", "Nb_palik", "Ni_palik", "Rh", "Rh_palik", "Se", "Se-e", "Se-e_palik", "Se_palik", "SiC", "SiC_palik", "SnTe", "SnTe_palik", "Ta", "Ta_palik", "Te", "Te-e", "Te-e_palik", "Te_palik", "ThF4", "ThF4_palik", "TiC", "TiC_palik", "TiN", "TiN_palik", "TiO2", "TiO2-e", "TiO2-e_palik", "TiO2_palik", "VC", "VC_palik", "VN", "VN_palik", "V_palik", "W", "a-C", "d-C", "d-C_palik", "none"]


class Conductor(_Material):
    """Metal: `preset` is a Mitsuba material name (Au, Ag, Cu, Al, Cr ...) or `none`
    (a perfect mirror); roughness 0 is smooth, > 0 uses a GGX microfacet model."""

    type: Literal["conductor"]
    preset: ConductorPreset = "Al"
    roughness: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 0.0  # a texture: grey, GGX alpha = its square
    tint: ColorOrTexture = 1.0  # scales the reflectance; a texture: RGB over the uv


class Dielectric(_Material):
    """Glass-like: reflects and refracts with index `ior`; smooth or rough. A solid
    interface: its two faces are inside and outside, so `two_sided` is refused."""

    type: Literal["dielectric"]
    ior: Annotated[float, Field(gt=1, le=4)] = 1.5
    roughness: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 0.0  # a texture: grey, GGX alpha = its square
    tint: ColorOrTexture = 1.0  # scales the transmittance; a texture: RGB over the uv

    @field_validator("two_sided")
    @classmethod
    def _transmissive(cls, value: bool) -> bool:
        if value:
            raise ValueError("a transmissive material has no front and back to make alike (Mitsuba's twosided refuses it); remove two_sided")
        return value


class ThinDielectric(Dielectric):
    """A thin pane (window glass, a soap film): reflects and transmits with index `ior`
    without bending the ray (Mitsuba `thindielectric`); smooth only."""

    type: Literal["thindielectric"]  # type: ignore[assignment]
    roughness: Annotated[float, Field(ge=0, le=0)] = 0.0  # type: ignore[assignment]


class Principled(_Material):
    """Disney-style principled BSDF: base colour, metallic, roughness, specular, clearcoat."""

    type: Literal["principled"]
    color: ColorOrTexture = 0.5
    metallic: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 0.0  # a texture: grey, raw
    roughness: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 0.5  # a texture: grey, raw
    specular: Annotated[float, Field(ge=0, le=1)] = 0.5
    clearcoat: Union[Annotated[float, Field(ge=0, le=1)], Texture] = 0.0  # a texture: grey, raw


Material = Annotated[
    Union[Diffuse, Plastic, Conductor, Dielectric, ThinDielectric, Principled],
    Field(discriminator="type"),
]


# --- objects ------------------------------------------------------------------------------


class Emission(Model):
    """Makes the shape an area light; radiance in W sr^-1 m^-2 per channel (or an RGB
    texture over the surface's uv)."""

    radiance: ColorOrTexture = 1.0


class Collider(Model):
    """Marks a static or keyed object as a collision surface for the simulation."""

    restitution: Annotated[float, Field(ge=0, le=1)] = 0.5
    friction: NonNegative = 0.3  # kinetic coefficient
    static_friction: NonNegative | None = None  # defaults to the kinetic one


class _Object(Model):
    """What every object has; the properties below say what kind of thing it is, so no
    stage asks `getattr(o, "deform", ...)` or tests classes itself."""

    spawned: ClassVar[bool] = False  # its geometry is spawned by the simulation (a particle system)

    name: Name
    transform: Transform = Transform.default()
    material: Name | None = None
    emission: Emission | None = None
    parent: Name | None = None
    motion: MotionBlock = StaticMotion.default()
    collider: Collider | None = None
    visible: bool = True
    deform: Deformation | None = None

    @property
    def is_particles(self) -> bool:
        """A particle system: particles spawned and moved by the dynamics stage."""
        return self.spawned

    @property
    def is_flock(self) -> bool:
        """A flock (`deform: {type: flock}`): its agents are simulated by the dynamics stage."""
        return self.deform is not None and self.deform.type == "flock"

    @property
    def is_nonrigid(self) -> bool:
        """Its vertices move relative to each other (a particle system or any `deform`): it
        renders as a particle system or a deforming mesh (render/translate/deforming.py),
        not as a rigid mover."""
        return self.spawned or self.deform is not None

    @property
    def has_follower(self) -> bool:
        """It follows a planned path as a simulated vehicle (`motion: plan` with `follower`)."""
        return self.motion.type == "plan" and self.motion.follower is not None

    @property
    def needs_simulation(self) -> bool:
        """Its motion or geometry comes from the dynamics stage: a dynamics body, a particle
        system, a flock or a path follower."""
        return self.motion.type == "dynamics" or self.spawned or self.is_flock or self.has_follower


class Sphere(_Object):
    """A sphere of `radius` (metres) centred at the object's origin."""

    shape: Literal["sphere"]
    radius: Positive = 1.0


class Cube(_Object):
    """An axis-aligned box of side `size` (metres), centred at the origin before transform."""

    shape: Literal["cube"]
    size: Size3 = (1.0, 1.0, 1.0)


class Rectangle(_Object):
    """A `width` x `height` rectangle in the object's XY plane, normal +Z."""

    shape: Literal["rectangle"]
    width: Positive = 1.0
    height: Positive = 1.0


class Disk(_Object):
    """A disk in the object's XY plane, normal +Z."""

    shape: Literal["disk"]
    radius: Positive = 1.0


class Cylinder(_Object):
    """A capped cylinder along the object's +Y axis, centred at the origin."""

    shape: Literal["cylinder"]
    radius: Positive = 1.0
    height: Positive = 1.0


class Capsule(_Object):
    """A capsule along the object's +Y axis, centred at the origin: a cylinder of `radius`
    and `height` (between the centres of its two hemispherical caps) closed by the caps;
    its whole length is height + 2 radius."""

    shape: Literal["capsule"]
    radius: Positive = 0.5
    height: Positive = 1.0


class Mesh(_Object):
    """A triangle mesh from an .obj or .ply file, path relative to the scene file."""

    shape: Literal["mesh"]
    file: str
    face_normals: bool = False

    @field_validator("file")
    @classmethod
    def _ext(cls, value: str) -> str:
        if not value.lower().endswith((".obj", ".ply")):
            raise ValueError(f"mesh file must be .obj or .ply, got {value!r}")
        return value


class Empty(_Object):
    """A transform with no geometry (a locator or rig joint): a parent for other things."""

    shape: Literal["empty"]


class Particles(_Object):
    """A particle system: particles spawned by `emitter`, simulated by the dynamics stage,
    rendered as spheres of `radius`."""

    spawned = True

    shape: Literal["particles"]
    radius: Positive = 0.02
    emitter: ParticleEmitter


SceneObject = Annotated[
    Union[Sphere, Cube, Rectangle, Disk, Cylinder, Capsule, Mesh, Empty, Particles],
    Field(discriminator="shape"),
]


# --- render and output --------------------------------------------------------------------


class RenderSettings(Model):
    """How frames are rendered: resolution, samples, integrator and depth, motion blur,
    seeds, Mitsuba variant, filter, denoising."""

    resolution: tuple[Annotated[int, Field(ge=1, le=16384)], Annotated[int, Field(ge=1, le=16384)]] = (640, 360)
    spp: Annotated[int, Field(ge=1, le=1 << 20)] = 64
    integrator: Literal["path", "direct"] = "path"
    max_depth: Annotated[int, Field(ge=1, le=64)] = 8
    rr_depth: Annotated[int, Field(ge=1, le=64)] = 5
    motion_blur: Literal["stochastic", "subframes", "off"] = "stochastic"
    subframes: Annotated[int, Field(ge=1, le=256)] = 8  # K for motion_blur: subframes
    shutter_samples: Annotated[int, Field(ge=2, le=256)] = 9  # baked samples across the shutter
    time_slices: Annotated[int, Field(ge=1, le=64)] = 4  # a deforming mesh's residual templates across the shutter: what its fitted rigid track leaves, crossfaded (render/translate/deforming.py)
    seed: Annotated[int, Field(ge=0, lt=2**31)] = 0
    seed_policy: Literal["per-frame", "fixed"] = "per-frame"
    variant: Literal["auto", "llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb"] = "auto"
    filter: Literal["box", "gaussian", "tent"] = "gaussian"
    # denoise each frame in the worker (Intel Open Image Denoise, albedo + normal guides)
    denoise: Literal["off", "oidn"] = "off"
    # temporal stability of the denoised frames (docs/denoise.md): off | reproject
    temporal: Literal["off", "reproject"] = "off"

    @field_validator("motion_blur", "denoise", "temporal", mode="before")
    @classmethod
    def _yaml_off(cls, value: object) -> object:
        # YAML 1.1 reads a bare `off` as false: take it as the user meant it
        return "off" if value is False else value

    @model_validator(mode="after")
    def _temporal_needs_denoise(self) -> "RenderSettings":
        if self.temporal != "off" and self.denoise == "off":
            raise ValueError(f"temporal: {self.temporal} blends the noisy images of neighbouring frames before denoising them: it needs denoise: oidn")
        return self


class OutputSettings(Model):
    """Where and how frames are written: folder, file name pattern, EXR pixel type and
    compression, extra passes (AOVs), metadata."""

    directory: str | None = None  # default: out/<scene name>; `-o DIR` overrides
    filename: Annotated[str, Field(pattern=r"#+")] = "{name}.####.exr"
    pixel_type: Literal["half", "float"] = "half"
    compression: Literal["zip", "zips", "piz", "zstd", "none"] = "zip"
    aovs: list[Literal["depth", "normal", "motion", "albedo"]] = []
    # made after a render of the whole shot (a gapless run of frames); `--deliver` overrides
    deliver: list[Literal[DELIVER_NAMES]] = []  # type: ignore[valid-type]  # the registry's names (pipeline/deliverables.py)
    owner: str | None = None
    comments: str | None = None

    def frame_name(self, scene_name: str, frame: int) -> str:
        """`{name}.####.exr` -> `cannonball.0012.exr` (the run of # sets the padding)."""
        import re

        pattern = self.filename.replace("{name}", scene_name)
        run = re.search(r"#+", pattern)
        if run is None:  # the field pattern guarantees a run of '#'
            raise ValueError(f"output.filename {self.filename!r} has no run of '#' for the frame number")
        digits = f"{frame:0{len(run.group(0))}d}" if frame >= 0 else f"-{-frame:0{len(run.group(0))}d}"
        return pattern[: run.start()] + digits + pattern[run.end() :]


class Scene(Model):
    """A whole shot. `version` is the scene format's version."""

    version: Literal[1] = 1
    name: Name | None = None
    imports: list[ImportSpec] = []  # glTF / USD files expanded into the lists below (docs/imports.md)
    timeline: TimelineSpec = TimelineSpec.default()
    camera: Camera
    lights: list[Light] = []
    materials: list[Material] = []
    objects: list[SceneObject] = []
    dynamics: DynamicsSettings = DynamicsSettings.default()
    ik: list[IKConstraint] = []  # inverse kinematics on parented chains (motion/ik.py)
    render: RenderSettings = RenderSettings.default()
    output: OutputSettings = OutputSettings.default()


class Preset(Model):
    """A render preset (configs/NAME.yaml, presets.py): render and output settings merged
    over the scene, and how many frames to spread over the timeline. A record of the scene
    stage, so its validator is kept between processes like the scene's (compiled.py)."""

    description: str = ""
    frame_count: int | None = Field(default=None, ge=1)
    render: dict[str, Any] = {}
    output: dict[str, Any] = {}


__all__ = [
    "Camera",
    "Capsule",
    "Collider",
    "ConstantLight",
    "Cube",
    "Cylinder",
    "Dielectric",
    "Diffuse",
    "DirectionalLight",
    "Disk",
    "Emission",
    "Empty",
    "EnvmapLight",
    "FiniteFloat",
    "ImportSpec",
    "Preset",
    "LIGHT_TYPES",
    "Light",
    "Material",
    "Mesh",
    "NonNegative",
    "OutputSettings",
    "Particles",
    "PointLight",
    "ProjectorLight",
    "Principled",
    "Plastic",
    "Rectangle",
    "RenderSettings",
    "Scene",
    "SceneObject",
    "Shutter",
    "Sphere",
    "SpotLight",
    "Conductor",
    "TimelineSpec",
    "Vec3",
]
