"""What a frame's EXR header says about how it was made, and what of it makes a frame and
its reference another picture.

A frame rendered by `motion render` carries `motion:` attributes (render/worker/job.py `_header`):
the frame's identity (identity/record.py, docs/identity.md: the look's parts, `look_parts`,
read by `stored_parts`, and the digest of its own baked motion, `motion_hash`: what reruns
compare), the render settings as JSON
(`render_settings`), the renderer's version, the Mitsuba variant, the seed and the samples
per pixel. A seed, a variant (CPU or GPU), a thread count or a machine change only the
noise, and the scene file's bytes (a comment, a name) not even that: none of them is noted.
A changed look part (a material, an object, a light, the camera), motion, setting or
renderer is compared all the same and named as a note (`notes`); only frames of other sizes
cannot be compared (`incomparable`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import FrameIOError
from ..frame_output import META_PREFIX, check_data_window, read_header
from ..identity.record import stored_parts

# settings that change only the noise of a frame, never what it converges to
NOISE_ONLY = frozenset({"seed", "seed_policy", "variant"})
# settings of how a frame is stored, not what it shows (a golden set is half floats)
STORAGE = frozenset({"pixel_type", "compression", "aovs"})
# look parts said otherwise: the render settings by name (without the seed), the renderer by version
_PARTS_SAID_APART = frozenset({"render", "renderer"})
_PART_NAMES = {"camera": "the camera", "roles": "which objects and lights move"}
_PART_KINDS = {"m": "material", "o": "object", "l": "light"}


@dataclass(frozen=True)
class FrameFacts:
    """How one frame was made, from its header: scene digest, render settings (those that
    decide what it converges to), renderer, variant, seed, spp; `width` x `height`."""

    path: Path
    width: int
    height: int
    scene: str | None = None
    scene_digest: str | None = None
    renderer: str | None = None
    variant: str | None = None
    seed: int | None = None
    spp: int | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    look_parts: dict[str, str] | None = None
    motion_hash: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain data for a manifest or report."""
        return {"scene": self.scene, "scene_digest": self.scene_digest, "renderer": self.renderer, "variant": self.variant,
                "seed": self.seed, "spp": self.spp, "resolution": [self.width, self.height], "settings": self.settings,
                "look_parts": self.look_parts, "motion_hash": self.motion_hash}


def facts_from_header(path: Path, header: Mapping[str, Any]) -> FrameFacts:
    """The facts of the frame at `path` from its (already read) header."""
    meta = {k[len(META_PREFIX):]: v for k, v in header.items() if k.startswith(META_PREFIX)}
    lo, hi = header["dataWindow"]
    settings: dict[str, Any] = {}
    raw = meta.get("render_settings")
    if isinstance(raw, (str, bytes)):
        try:
            loaded = json.loads(raw, parse_constant=lambda _: None, parse_float=_finite_float)  # a manifest holds no NaN
            if isinstance(loaded, dict):
                settings = {k: v for k, v in loaded.items() if k not in NOISE_ONLY}
        except (ValueError, RecursionError):
            settings = {}

    def _int(value: Any) -> int | None:
        try:
            return int(value)
        except (TypeError, ValueError):
            return None

    def _str(value: Any) -> str | None:
        return value.decode(errors="replace") if isinstance(value, bytes) else (str(value) if value is not None else None)

    return FrameFacts(path=path, width=int(hi[0]) - int(lo[0]) + 1, height=int(hi[1]) - int(lo[1]) + 1,
                      scene=_str(meta.get("scene")), scene_digest=_str(meta.get("scene_hash")), renderer=_str(meta.get("renderer")),
                      variant=_str(meta.get("variant")), seed=_int(meta.get("seed")), spp=_int(meta.get("spp")), settings=settings,
                      look_parts=stored_parts(meta.get("look_parts")), motion_hash=_str(meta.get("motion_hash")))


def _finite_float(text: str) -> float | None:
    """A JSON number as a float, or None when it is out of range (1e400)."""
    value = float(text)
    return value if math.isfinite(value) else None


def find_frames(folder: str | Path, prefix: str | None = None) -> tuple[str, dict[int, Path]]:
    """(name, {frame number: file}) of the `prefix`.NNNN.exr sequence in `folder` (the only
    one when `prefix` is None). Nothing is read or allocated by the span of the numbers (a
    folder may hold frames 0 and 2**31). FrameIOError for a folder without it, several
    sequences, or one number written twice."""
    from ..telecine.sequence import choose_sequence

    folder = Path(folder)
    prefix, items = choose_sequence(folder, prefix)
    out: dict[int, Path] = {}
    for number, path in items:
        if number in out:
            raise FrameIOError(f"{folder}: frame {number} appears twice ({out[number].name}, {path.name})")
        out[number] = path
    return prefix, out


def frame_facts(path: Path) -> FrameFacts:
    """The facts of the frame at `path` (FrameIOError if it cannot be read)."""
    return facts_from_header(path, read_header(path))


def incomparable(new: Mapping[str, Any], ref: Mapping[str, Any]) -> list[str]:
    """What makes NEW and REF (FrameFacts.to_dict()) impossible to compare pixel by pixel, as
    phrases: their sizes. Empty when they can be compared."""
    a, b = new.get("resolution"), ref.get("resolution")
    if a is not None and b is not None and list(a) != list(b):
        return [f"resolution {'x'.join(map(str, a))} (new) vs {'x'.join(map(str, b))} (reference)"]
    return []


def part_name(part: str, names: Mapping[str, str] | None = None) -> str:
    """A look part's name for a note: `m1` -> 'material 2 of the scene (m1)', or with the
    scene's `names` (identity/look.py part_names) 'material iron (m1)'."""
    if names and part in names:
        return f"{names[part]} ({part})"
    if part in _PART_NAMES:
        return _PART_NAMES[part]
    kind, number = part[:1], part[1:]
    if kind in _PART_KINDS and number.isdigit() and len(number) < 10:
        return f"{_PART_KINDS[kind]} {int(number) + 1} of the scene ({part})"
    return f"look part {part}"


def notes(new: Mapping[str, Any], ref: Mapping[str, Any], names: Mapping[str, str] | None = None) -> list[str]:
    """How NEW and REF (FrameFacts.to_dict()) were made differently though they can be
    compared, as phrases: the renderer's version, each look part (material, object, light,
    camera) and render setting that differs (noise-only and storage ones excepted), the
    frame's motion. The scene file's bytes count only when a frame has no look key (a
    comment or a name changes no picture). Empty when they are the same picture. `names`:
    what each look part is called in the new frames' scene, when known."""
    out = []
    a, b = new.get("renderer"), ref.get("renderer")
    if a is not None and b is not None and a != b:
        out.append(f"renderer version {a} (new) vs {b} (reference)")
    pa, pb = new.get("look_parts"), ref.get("look_parts")
    if isinstance(pa, dict) and isinstance(pb, dict):
        for part in sorted(set(pa) | set(pb), key=_part_order):
            if part not in _PARTS_SAID_APART and pa.get(part) != pb.get(part):
                said = "differs" if part in pa and part in pb else ("is new" if part in pa else "is gone")
                out.append(f"{part_name(part, names)} {said}")
    else:
        da, db = new.get("scene_digest"), ref.get("scene_digest")
        if da is not None and db is not None and da != db:
            out.append(f"scene file {da} (new) vs {db} (reference), and the frames carry no look key to say what changed")
    sa, sb = new.get("settings") or {}, ref.get("settings") or {}
    for key in sorted(set(sa) | set(sb)):
        if key not in NOISE_ONLY and key not in STORAGE and sa.get(key) != sb.get(key):
            out.append(f"render setting {key} {_shown(sa.get(key))} (new) vs {_shown(sb.get(key))} (reference)")
    ma, mb = new.get("motion_hash"), ref.get("motion_hash")
    if ma is not None and mb is not None and ma != mb:
        out.append("the frame's motion differs")
    return out


def _shown(value: Any) -> str:
    """A setting's value in a note (JSON; never a non-finite number token)."""
    try:
        return json.dumps(value, allow_nan=False, sort_keys=True)
    except (ValueError, TypeError):
        return repr(value)


def _part_order(part: str) -> tuple[str, int, str]:
    """Look parts in the scene's order: camera, m0, m1, ..., o0, ..., l0, ..."""
    kind, number = part[:1], part[1:]
    return (kind, int(number), part) if kind in _PART_KINDS and number.isdigit() and len(number) < 10 else (part, 0, part)


def read_pixels(path: str | Path, layer: str) -> tuple[dict[str, Any], np.ndarray, np.ndarray | None]:
    """(header, RGBA float32 [H, W, 4], the layer `layer` as float32 [H, W, C] or None) of a
    frame: only what a comparison reads is converted (frame_output.read_frame converts every
    layer: 2-3 times the time on a frame with albedo and normal layers). FrameIOError for a
    missing or unreadable file, like read_frame."""
    import OpenEXR

    path = Path(path)
    check_data_window(path, read_header(path))  # before a pixel is allocated
    try:
        with OpenEXR.File(str(path)) as f:
            header = dict(f.header())
            chans = f.channels()
            if "RGBA" in chans:
                rgba = np.asarray(chans["RGBA"].pixels, dtype=np.float32)
            elif "RGB" in chans:
                rgb = np.asarray(chans["RGB"].pixels, dtype=np.float32)
                rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
            else:
                raise FrameIOError(f"{path}: no RGB or RGBA channels (has {sorted(chans)})")
            extra: np.ndarray | None = None
            if layer in chans:  # the bindings group <layer>.R/G/B/A as one channel
                extra = np.asarray(chans[layer].pixels, dtype=np.float32)
                extra = extra[..., None] if extra.ndim == 2 else extra
            else:
                comps = [c for c in "RGBA" if f"{layer}.{c}" in chans]
                if comps:
                    extra = np.stack([np.asarray(chans[f"{layer}.{c}"].pixels, dtype=np.float32) for c in comps], axis=2)
    except FrameIOError:
        raise
    except Exception as exc:  # the bindings raise RuntimeError for any bad file
        raise FrameIOError(f"{path}: not a readable OpenEXR file ({exc})") from None
    return header, rgba, extra
