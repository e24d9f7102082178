"""What a frame's EXR header says about how it was made, and which of those facts may
differ between a frame and its reference.

A frame rendered by `motion render` carries `motion:` attributes (render/job.py `_header`):
the scene file's digest (`scene_hash`), the render settings as JSON (`render_settings`),
the renderer's version, the Mitsuba variant, the seed and the samples per pixel. A seed,
a variant (CPU or GPU), a thread count or a machine change only the noise: those may
differ. Anything else in the settings, or the scene's digest, makes a comparison
meaningless unless the user asks for it (`--allow-different-settings`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import FrameIOError
from ..frame_output import META_PREFIX, check_data_window, read_header

# settings that change only the noise of a frame, never what it converges to
NOISE_ONLY = frozenset({"seed", "seed_policy", "variant"})


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

    def to_dict(self) -> dict[str, Any]:
        """Plain data for a manifest or report."""
        return {"scene": self.scene, "scene_digest": self.scene_digest, "renderer": self.renderer, "variant": self.variant,
                "seed": self.seed, "spp": self.spp, "resolution": [self.width, self.height], "settings": self.settings}


def facts_from_header(path: Path, header: Mapping[str, Any]) -> FrameFacts:
    """The facts of the frame at `path` from its (already read) header."""
    meta = {k[len(META_PREFIX):]: v for k, v in header.items() if k.startswith(META_PREFIX)}
    lo, hi = header["dataWindow"]
    settings: dict[str, Any] = {}
    raw = meta.get("render_settings")
    if isinstance(raw, (str, bytes)):
        try:
            loaded = json.loads(raw)
            if isinstance(loaded, dict):
                settings = {k: v for k, v in loaded.items() if k not in NOISE_ONLY}
        except ValueError:
            settings = {}

    def _int(value: Any) -> int | None:
        try:
            return int(value)
        except (TypeError, ValueError):
            return None

    def _str(value: Any) -> str | None:
        return value.decode() if isinstance(value, bytes) else (str(value) if value is not None else None)

    return FrameFacts(path=path, width=int(hi[0]) - int(lo[0]) + 1, height=int(hi[1]) - int(lo[1]) + 1,
                      scene=_str(meta.get("scene")), scene_digest=_str(meta.get("scene_hash")), renderer=_str(meta.get("renderer")),
                      variant=_str(meta.get("variant")), seed=_int(meta.get("seed")), spp=_int(meta.get("spp")), settings=settings)


def frame_facts(path: Path) -> FrameFacts:
    """The facts of the frame at `path` (FrameIOError if it cannot be read)."""
    return facts_from_header(path, read_header(path))


def differences(new: Mapping[str, Any], ref: Mapping[str, Any]) -> list[str]:
    """What makes NEW and REF (FrameFacts.to_dict(), or a manifest's) not comparable, as
    phrases: the scene digest, the renderer version, each render setting that differs
    (noise-only ones excepted), the resolution. Empty when they are comparable."""
    out = []
    for key, label in (("scene_digest", "scene digest"), ("renderer", "renderer version"), ("resolution", "resolution")):
        a, b = new.get(key), ref.get(key)
        if a is not None and b is not None and a != b:
            shown = (lambda v: "x".join(map(str, v))) if key == "resolution" else str
            out.append(f"{label} {shown(a)} (new) vs {shown(b)} (reference)")
    sa, sb = new.get("settings") or {}, ref.get("settings") or {}
    for key in sorted(set(sa) | set(sb)):
        if key in NOISE_ONLY:
            continue
        if sa.get(key) != sb.get(key):
            out.append(f"render setting {key} {json.dumps(sa.get(key))} (new) vs {json.dumps(sb.get(key))} (reference)")
    return out


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
