"""The smallest scene the input tests start from (one ball, three frames at 24 fps, 16x12,
1 sample, scalar_rgb): each test writes it with the one field it breaks or changes."""

from __future__ import annotations

from typing import Any

BASE = """\
timeline: {fps: 24, first: 0, last: 2}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
lights: [{type: constant, radiance: 0.5}]
render: {resolution: [16, 12], spp: 1, max_depth: 2, shutter_samples: 2, variant: scalar_rgb}
objects:
  - {name: ball, shape: sphere, radius: 0.5}
"""

TWO_FRAMES = BASE.replace("last: 2", "last: 1")  # two frames


# A fountain of orange sparks rising over a grey sky, denser and higher as it runs: the
# particle tests count its orange pixels (`orange_pixels`)
FOUNTAIN = """
timeline: {fps: 24, first: 0, last: 12}
camera: {position: [0, 1.5, 6], look_at: [0, 1.2, 0], fov: 45}
lights: [{type: constant, radiance: 0.5}]
materials: [{name: spark, type: diffuse, color: [0.9, 0.5, 0.0]}]
objects:
  - name: fountain
    shape: particles
    radius: 0.04
    material: spark
    emitter: {rate: 1500, lifetime: 2.0, position: [0, 0.1, 0], direction: [0, 1, 0], speed: 5, spread: 20, seed: 3}
render: {resolution: [64, 48], spp: 4, max_depth: 2, shutter_samples: 5}
"""


def orange_pixels(img: Any) -> int:
    """How many pixels of an RGB(A) image [H, W, >=3] are orange (red over green over blue)."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((r > g + 0.05) & (g > b + 0.05)).sum())


# The two-bone arm a skinning deformer bends: `upper` from y=-1 to 0, `lower` from 0 to 1,
# `lower` keyed from 0 to 90 degrees about z over the first second (frame 24 at 24 fps).
# The `bones:` block of an object's `deform:` (indented for it); the deformation tests and
# the render of a skinned mesh start from it.
ARM_BONES = """\
      bones:
        - {name: upper, transform: {translate: [0, -1, 0]}, length: 1}
        - name: lower
          parent: upper
          transform: {translate: [0, 1, 0]}
          length: 1
          motion:
            type: keyframes
            time_unit: seconds
            channels: {rotate: {keys: [{time: 0, euler: [0, 0, 0]}, {time: 1, euler: [0, 0, 90]}]}}
"""

# An object entry of `objects:` wearing ARM_BONES: a 0.3 x 2 x 0.3 cube standing from y=0
# to 2 (the bones in its object space), material `arm`, auto weights.
SKINNED_ARM = """\
  - name: arm
    shape: cube
    size: [0.3, 2.0, 0.3]
    material: arm
    transform: {translate: [0, 1, 0]}
    deform:
      type: skinning
      auto: true
""" + ARM_BONES
