"""A frame's identity: what makes two frames the same frame (docs/identity.md), in one
place for reruns (`--resume`), `--check`, compare, deliverable versions and ship mode.

- `inputs`: the scene-wide inputs: the renderer's version, the render settings, the files
  the scene names by their bytes, the scene and settings hashes a job carries.
- `look`: the look half of a frame's key, one digest per material, object, light, camera.
- `motion_digest`: the motion half, the digest of a frame's own baked motion (per moving
  thing too), objects and lights by their place in the scene.
- `record`: `FrameIdentity`, its attributes in a frame's header, whether a frame on disk
  is complete as that identity and, when not, why.
- `kept`: each frame's identity and the look kept in the cache layer by the settings
  digest, so a rerun that renders nothing decides so without baking.
"""

from __future__ import annotations

from .inputs import RENDERER_VERSION, content_named, file_digests, render_settings, scene_file_hash, scene_hashes, settings_digest
from .look import MOVING, look_hash, look_parts, part_names
from .motion_digest import Order, fingerprint, frame_digests, leaves
from .record import MAX_PARTS, CurrentKeys, FrameIdentity, complete_as, frame_identity, header_attributes, recorded_keys, why_stale

__all__ = [
    "MAX_PARTS",
    "MOVING",
    "RENDERER_VERSION",
    "CurrentKeys",
    "FrameIdentity",
    "Order",
    "complete_as",
    "content_named",
    "file_digests",
    "fingerprint",
    "frame_digests",
    "frame_identity",
    "header_attributes",
    "leaves",
    "look_hash",
    "look_parts",
    "part_names",
    "recorded_keys",
    "render_settings",
    "scene_file_hash",
    "scene_hashes",
    "settings_digest",
    "why_stale",
]
