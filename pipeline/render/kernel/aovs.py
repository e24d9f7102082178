"""The AOV table: every arbitrary output the integrator can compute, in one place.

Each AOV has the name a scene asks for (`output.aovs`), the EXR layer it is written to and
that layer's channels. The integrator emits the channels of the AOVs it computes in this
table's order, after RGBA; the worker splits them into layers by the same table
(`split_layers`); the denoiser and the temporal pass read the layers by `layer(name)`.

| AOV | layer | channels | value (first hit) |
|---|---|---|---|
| depth | Z | Z | camera-space depth along the view axis, camera at the sample's time |
| normal | N | N.X N.Y N.Z | world-space shading normal |
| motion | motion | motion.X motion.Y | screen pixels moved from shutter open to close, +x right, +y down |
| albedo | albedo | albedo.R albedo.G albedo.B | the denoiser's guide (the integrator's `_albedo`) |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:
    import numpy as np


@dataclass(frozen=True)
class Aov:
    """One AOV: its scene name, its EXR layer, and the layer's channel suffixes (none: a
    one-channel layer named by the layer alone, as OpenEXR's `Z`)."""

    name: str
    layer: str
    suffixes: tuple[str, ...] = ()

    @property
    def channels(self) -> list[str]:
        """The EXR channel names, in the order the integrator emits them."""
        return [f"{self.layer}.{s}" for s in self.suffixes] if self.suffixes else [self.layer]


AOVS: tuple[Aov, ...] = (
    Aov("depth", "Z"),
    Aov("normal", "N", ("X", "Y", "Z")),
    Aov("motion", "motion", ("X", "Y")),
    Aov("albedo", "albedo", ("R", "G", "B")),
)
BY_NAME: dict[str, Aov] = {a.name: a for a in AOVS}


def layer(name: str) -> str:
    """The EXR layer of AOV `name` ('normal' -> 'N')."""
    return BY_NAME[name].layer


def computed(wanted: Sequence[str]) -> list[Aov]:
    """The AOVs among `wanted` (names), in the table's order: the integrator's order."""
    return [a for a in AOVS if a.name in wanted]


def channel_names(wanted: Sequence[str]) -> list[str]:
    """The integrator's AOV channel names (after RGBA) for the AOVs `wanted`."""
    return [c for a in computed(wanted) for c in a.channels]


def split_layers(image: np.ndarray, wanted: Sequence[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """RGBA [H, W, 4] and the AOV layers of the film's image [H, W, 4 + AOV channels]: a
    one-channel layer is [H, W] (Z), the others [H, W, C] (N, motion, albedo)."""
    layers: dict[str, np.ndarray] = {}
    index = 4
    for aov in computed(wanted):
        count = len(aov.channels)
        layers[aov.layer] = image[..., index] if not aov.suffixes else image[..., list(range(index, index + count))]
        index += count
    return image[..., :4], layers
