"""The smallest scene the input tests start from (one ball, three frames at 24 fps, 16x12,
1 sample, scalar_rgb): each test writes it with the one field it breaks or changes."""

from __future__ import annotations

BASE = """\
timeline: {fps: 24, first: 0, last: 2}
camera: {position: [0, 1, 5], look_at: [0, 0, 0]}
lights: [{type: constant, radiance: 0.5}]
render: {resolution: [16, 12], spp: 1, max_depth: 2, shutter_samples: 2, variant: scalar_rgb}
objects:
  - {name: ball, shape: sphere, radius: 0.5}
"""

TWO_FRAMES = BASE.replace("last: 2", "last: 1")  # two frames


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
