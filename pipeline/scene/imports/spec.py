"""Scene format v1: the `imports:` entries (docs/imports.md).

    imports:
      - file: assets/walker.glb        # .gltf .glb .usd .usda .usdc, relative to the scene
        prefix: "walker."              # prepended to every imported name
        transform: {translate: [0, 0, 2]}   # the import's root frame in the shot
        animation: walk                # glTF: which animation (name or index); default the first
        overrides:                     # imported objects and lights by (prefixed) name
          walker.Body: {material: red}
"""

# No `from __future__ import annotations` in the schema modules: pydantic would then compile
# and evaluate every field's annotation string when each model class is made, in every
# process that loads a scene (docs/ci-sharding.md, "What validation keeps").

from typing import Annotated, Any, Literal, Union

from pydantic import Field, field_validator

from ..types import FiniteFloat, Model, NonNegative, Positive, Transform

IMPORT_SUFFIXES = (".gltf", ".glb", ".usd", ".usda", ".usdc")
PREFIX_PATTERN = r"^([A-Za-z_][A-Za-z0-9_.\-]*)?$"


class ImportSpec(Model):
    """One asset file brought into the shot: its node (prim) tree becomes parent frames,
    its meshes, materials, lights, camera and animation the same records a hand-written
    scene has. `root` names the empty that carries `transform` (default: prefix + file stem)."""

    file: str
    prefix: Annotated[str, Field(pattern=PREFIX_PATTERN, max_length=64)] = ""
    root: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_.\-]*$", max_length=128)] | None = None
    transform: Transform = Transform.default()
    scene: Union[Annotated[int, Field(ge=0)], str, None] = None  # glTF: which scene (default: the file's)
    nodes: list[str] | None = None  # glTF node / USD prim names: import only these subtrees
    # glTF: a name or index, "*" for all at once, -1 for none; default: all when they key
    # disjoint nodes (Blender writes one animation per object), else the first
    animation: Union[Annotated[int, Field(ge=-1)], str, None] = None
    camera: str | None = None  # the camera node (prim) that becomes the shot's camera
    light_scale: NonNegative = 1.0  # multiplies imported light intensities (docs/imports.md, units)
    time_offset: FiniteFloat = 0.0  # seconds: the file's time 0 plays at this scene time
    overrides: dict[str, dict[str, Any]] = {}
    # metres per file unit and the file's up axis; default: the file's (USD metersPerUnit
    # and upAxis where authored, else metres and +Y; glTF: metres, +Y)
    units: Positive | None = None
    up_axis: Literal["y", "z"] | None = None

    @field_validator("file")
    @classmethod
    def _suffix(cls, value: str) -> str:
        if not value.lower().endswith(IMPORT_SUFFIXES):
            raise ValueError(f"an import is a glTF (.gltf, .glb) or USD (.usd, .usda, .usdc) file, got {value!r}")
        return value


class ImportList(Model):
    """The `imports:` list alone, validated before the rest of the scene."""

    imports: list[ImportSpec] = []
