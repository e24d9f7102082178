"""Small shared value types of the scene format: vectors, colours, rotations, transforms.

Every model is frozen and rejects unknown keys (`extra="forbid"`); the loader turns
pydantic's errors into `FILE:LINE:COL: yaml.path: message` lines.
"""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

import math
from typing import Annotated, Any, Literal, Self, Union

from pydantic import AfterValidator, BaseModel, ConfigDict, Discriminator, Field, Tag, model_validator

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[FiniteFloat, FiniteFloat, FiniteFloat]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$", max_length=128)]


def _triple(value: float | tuple[float, float, float]) -> tuple[float, float, float]:
    """One number means the same on all three axes."""
    return (value, value, value) if isinstance(value, (int, float)) else tuple(value)  # type: ignore[return-value]


# A size or scale: one positive number or one per axis; read back always as (x, y, z).
Size3 = Annotated[Union[Positive, tuple[Positive, Positive, Positive]], AfterValidator(_triple)]
# A colour is RGB in linear units, or one grey value.
Color = Union[tuple[NonNegative, NonNegative, NonNegative], NonNegative]


class Model(BaseModel):
    """Base of every scene record: immutable, unknown keys rejected."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True, defer_build=True)

    @classmethod
    def default(cls) -> Self:
        """The record with every field at its default, for a field's default value: made
        without the class's validator, which `cls()` would build when the module is
        imported (most of that work again inside the scene's validator; docs/ci-sharding.md).
        Defaults are valid by construction; tests/cli/test_startup.py checks that each
        such default equals `cls()`."""
        return cls.model_construct()


class EulerRotation(Model):
    """Euler angles in degrees, applied in `order` about fixed (extrinsic, lowercase) or
    moving (intrinsic, uppercase) axes, as scipy's `Rotation.from_euler` reads them."""

    euler: Vec3
    order: Annotated[str, Field(pattern=r"^([xyz]{3}|[XYZ]{3})$")] = "xyz"


class AxisAngleRotation(Model):
    """A rotation of `angle` degrees about `axis` (need not be unit length)."""

    axis: Vec3
    angle: FiniteFloat

    @model_validator(mode="after")
    def _axis_nonzero(self) -> "AxisAngleRotation":
        if math.hypot(*self.axis) < 1e-12:
            raise ValueError("axis must not be the zero vector")
        return self


class QuaternionRotation(Model):
    """A rotation as a quaternion (w, x, y, z); normalised on load, must not be zero."""

    quaternion: tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat]

    @model_validator(mode="after")
    def _nonzero(self) -> "QuaternionRotation":
        if math.sqrt(sum(c * c for c in self.quaternion)) < 1e-12:
            raise ValueError("quaternion must not be zero")
        return self


def _rotation_kind(value: Any) -> str | None:
    """Pick the rotation form by the key it uses, so errors speak of that form only."""
    if isinstance(value, dict):
        for key, kind in (("euler", "euler"), ("axis", "axis-angle"), ("angle", "axis-angle"), ("quaternion", "quaternion")):
            if key in value:
                return kind
        return None
    if isinstance(value, BaseModel):
        return {EulerRotation: "euler", AxisAngleRotation: "axis-angle", QuaternionRotation: "quaternion"}.get(type(value))
    return None


Rotation = Annotated[
    Union[
        Annotated[EulerRotation, Tag("euler")],
        Annotated[AxisAngleRotation, Tag("axis-angle")],
        Annotated[QuaternionRotation, Tag("quaternion")],
    ],
    Discriminator(
        _rotation_kind,
        custom_error_type="rotation_form",
        custom_error_message="a rotation needs one of: euler (+ order), axis + angle, quaternion",
    ),
]


class Transform(Model):
    """world_from_object = T(translate) * R(rotate) * S(scale)."""

    translate: Vec3 = (0.0, 0.0, 0.0)
    rotate: Rotation | None = None
    scale: Size3 = (1.0, 1.0, 1.0)


class Texture(Model):
    """A bitmap texture (PNG, JPEG, EXR, HDR ...), path relative to the scene file."""

    file: str
    filter: Literal["bilinear", "nearest"] = "bilinear"
    wrap: Literal["repeat", "mirror", "clamp"] = "repeat"
    raw: bool = False  # true: data (roughness, normal), not colour: no sRGB decoding
    tile: Union[Positive, tuple[Positive, Positive]] = 1.0  # repeats across the surface (u, v)

