"""Light records: one class per light type, entered in LIGHT_TYPES (docs/architecture.md,
"One record per light type").

Each light type is one record: its fields, its emission channel, how its fields make its
frame (`frame`, given the motion stage's frame makers), whether that frame is rigid,
whether a moving one is posed per path, and the Mitsuba emitter it becomes (`emitter`,
plain values; the render stage converts matrices and colours). `@light_type` enters it in
LIGHT_TYPES, from which the `Light` union is made: adding a light type is one class here
(docs/architecture.md). scene/schema.py re-exports these names.
"""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

from typing import Annotated, Any, Callable, ClassVar, Literal, Protocol, Union, get_args

from pydantic import Field

from .motion_schema import MotionBlock, StaticMotion
from .types import Color, Model, Name, NonNegative, Transform, Vec3

LIGHT_TYPES: dict[str, type["_Light"]] = {}

# Where a camera, spot light or projector points: a fixed world point, or an object's name,
# tracked at every sample time (motion/evaluate.py aims at the object's world origin).
Aim = Annotated[
    Union[Vec3, Name],
    Field(description="a point [x, y, z] in the parent's frame, or the name of an object whose world origin is "
                      "tracked at every sample time (its parents, keys and simulation included), so the aim's "
                      "motion blur is right; an aim at an object sets the rotation: no rotating motion on top"),
]


def light_key(light: Any, index: int) -> str:
    """A light's key in the scene's motion and render records: its name, else `light<index>`
    (its place in `scene.lights`)."""
    return light.name if light.name is not None else f"light{index}"


class LightFrames(Protocol):
    """The frames a light's fields can make, in the light's parent's space; the motion stage
    supplies them (motion/evaluate.py), so this module stays free of the rotation math."""

    def identity(self) -> Any:
        """The parent's own frame."""

    def transformed(self, transform: Transform) -> Any:
        """A `transform:` block's translate, rotate and scale."""

    def at(self, position: Vec3) -> Any:
        """At `position`, unrotated."""

    def aimed(self, position: Vec3, look_at: "Vec3 | str") -> Any:
        """At `position`, its +Z towards `look_at`."""

    def along(self, direction: Vec3) -> Any:
        """Its +Z along `direction`, at the origin."""


class _Light(Model):
    """What every light has: a name, a parent, a motion block, and the class facts below."""

    channel: ClassVar[str]  # the emission quantity in the light's own units: the one scalar its motion may key
    channel_size: ClassVar[int] = 3  # 3: a colour (grey or RGB); 1: a number
    rigid_frame: ClassVar[bool] = False  # a scaled parent moves the light, never stretches its frame
    posed_per_path: ClassVar[bool] = False  # moving: posed at each path's own time by the integrator (a delta light)
    image_files: ClassVar[tuple[str, ...]] = ()  # fields naming an image file, opened and checked before any task
    environment: ClassVar[bool] = False  # a light at infinity around the whole scene: Mitsuba takes one a scene

    name: Name | None = None
    parent: Name | None = None
    motion: MotionBlock = StaticMotion.default()

    @property
    def emission(self) -> Any:
        """The light's own (unkeyed) value of its emission channel."""
        return getattr(self, self.channel)

    def frame(self, frames: LightFrames) -> Any:
        """The light's own frame from its fields, made by `frames`: the parent's, by default."""
        return frames.identity()

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """The Mitsuba emitter dictionary at one time: `value` is the emission channel's value
        then, `to_world` the light's frame (a 4x4 matrix, rigid when `rigid_frame`),
        `asset` resolves a file field to a path."""
        raise NotImplementedError(f"light type {type(self).__name__} has no emitter")


def extra_environments(lights: Any) -> list[tuple[int, int]]:
    """(index, index of the first) for every environment light after the first in `lights`:
    Mitsuba builds a scene with at most one environment emitter and refuses the second at
    every frame, so validation names each one."""
    first = next((i for i, light in enumerate(lights) if type(light).environment), None)
    return [(i, first) for i, light in enumerate(lights) if first is not None and i > first and type(light).environment]


def light_type(cls: type[_Light]) -> type[_Light]:
    """Enter a light record in LIGHT_TYPES under its `type` literal."""
    (name,) = get_args(cls.model_fields["type"].annotation)
    LIGHT_TYPES[name] = cls
    return cls


@light_type
class ConstantLight(_Light):
    """Uniform environment radiance (W sr^-1 m^-2 per channel)."""

    channel = "radiance"
    environment = True

    type: Literal["constant"]
    radiance: Color = 1.0

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `constant`."""
        return {"type": "constant", "radiance": value}


@light_type
class EnvmapLight(_Light):
    """Latitude-longitude environment map (EXR/HDR/PNG), path relative to the scene."""

    channel = "scale"
    channel_size = 1
    image_files = ("file",)
    environment = True

    type: Literal["envmap"]
    file: str
    scale: NonNegative = 1.0
    transform: Transform | None = None

    def frame(self, frames: LightFrames) -> Any:
        """Its `transform:`, else the parent's frame."""
        return frames.identity() if self.transform is None else frames.transformed(self.transform)

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `envmap`."""
        return {"type": "envmap", "filename": asset(self.file), "scale": value, "to_world": to_world}


@light_type
class PointLight(_Light):
    """Isotropic point light; intensity in W sr^-1 per channel."""

    channel = "intensity"
    rigid_frame = True
    posed_per_path = True

    type: Literal["point"]
    position: Vec3
    intensity: Color = 10.0

    def frame(self, frames: LightFrames) -> Any:
        """At `position`."""
        return frames.at(self.position)

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `point`."""
        return {"type": "point", "to_world": to_world, "intensity": value}


@light_type
class SpotLight(_Light):
    """Spot light at `position` shining towards `look_at`; intensity in W sr^-1 per channel on
    its axis; dark beyond `cutoff_angle`, full inside `beam_width` (default 3/4 of the cutoff,
    as Mitsuba's), a linear falloff in angle between."""

    channel = "intensity"
    rigid_frame = True
    posed_per_path = True

    type: Literal["spot"]
    position: Vec3
    look_at: Aim
    intensity: Color = 10.0
    cutoff_angle: Annotated[float, Field(gt=0, le=90)] = 20.0  # degrees
    beam_width: Annotated[float, Field(gt=0, le=90)] | None = None  # degrees, <= cutoff

    def frame(self, frames: LightFrames) -> Any:
        """At `position`, its axis towards `look_at`."""
        return frames.aimed(self.position, self.look_at)

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `spot` (a beam wider than the cutoff is the cutoff)."""
        d = {"type": "spot", "to_world": to_world, "intensity": value, "cutoff_angle": self.cutoff_angle}
        if self.beam_width is not None:
            d["beam_width"] = min(self.beam_width, self.cutoff_angle)
        return d


@light_type
class DirectionalLight(_Light):
    """Distant light (the sun); `direction` is where its light travels; irradiance in W m^-2
    per channel on a surface facing it."""

    channel = "irradiance"
    rigid_frame = True
    posed_per_path = True

    type: Literal["directional"]
    direction: Vec3
    irradiance: Color = 1.0

    def frame(self, frames: LightFrames) -> Any:
        """Its +Z along `direction`."""
        return frames.along(self.direction)

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `directional`."""
        return {"type": "directional", "to_world": to_world, "irradiance": value}


@light_type
class ProjectorLight(_Light):
    """A slide projector at `position` aimed at `look_at`: the image `file` spread over a
    frustum `fov` degrees wide (the image's width), its irradiance in W m^-2 per channel on
    a surface facing it 1 m away, the image's value times `scale` (Mitsuba `projector`)."""

    channel = "scale"
    channel_size = 1
    rigid_frame = True
    posed_per_path = True
    image_files = ("file",)

    type: Literal["projector"]
    position: Vec3
    look_at: Aim
    file: str
    fov: Annotated[float, Field(gt=0, lt=180)] = 30.0  # degrees, horizontal
    scale: NonNegative = 1.0

    def frame(self, frames: LightFrames) -> Any:
        """At `position`, aimed at `look_at`."""
        return frames.aimed(self.position, self.look_at)

    def emitter(self, value: Any, to_world: Any, asset: Callable[[str], str]) -> dict[str, Any]:
        """Mitsuba `projector` with the image as its irradiance texture."""
        return {"type": "projector", "to_world": to_world, "irradiance": {"type": "bitmap", "filename": asset(self.file)}, "fov": self.fov, "scale": value}


Light = Annotated[Union[tuple(LIGHT_TYPES.values())], Field(discriminator="type")]  # type: ignore[valid-type]
