"""A frame's identity: the record, its attributes in a frame's EXR header, and how two
frames' identities are compared (docs/identity.md).

Two frames are the same frame when they carry the same `FrameIdentity`: the frame number,
the look (every part of the scene that reaches the renderer other than motion, names left
out: identity/look.py) and the digest of the frame's own baked motion (identity/
motion_digest.py). What a rerun keeps (`--resume`), what `--check` counts complete, what a
shipped frame must carry when it comes home, what compare notes and what a deliverable's
version is made from all read this one record. The header also keeps the parts of the
look and motion digests and the render settings, so that a rerun says what differs
(`spp 16 -> 4`, `material iron changed`, `motion of box changed`), and the digest of the
pixels written (frame_output.py `pixels_sha256`), which names the picture itself.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

from ..bake.records import BakedFrame
from ..errors import FrameIOError
from ..frame_output import META_PREFIX, PIXELS_KEY, check_data_window, is_complete, pixel_digest, plain_meta, read_header, read_meta
from .inputs import RENDERER_VERSION, render_settings
from .look import MOVING
from .motion_digest import Order, frame_digests

MAX_PARTS = 1024  # parts listed by digest in a header (about 30 bytes each); a larger scene keeps its hashes only


@dataclass(frozen=True)
class FrameIdentity:
    """What makes two frames the same frame: its number, its look (`look_hash`, 16 hex
    digits) and the digest of its own baked motion (`motion_hash`, 16 hex digits); with
    the digest of each moving thing's motion (`motion_parts`, not compared: it names
    whose motion differs)."""

    frame: int
    look_hash: str
    motion_hash: str
    motion_parts: Mapping[str, str] = field(default_factory=dict, compare=False)

    def expected(self) -> dict[str, Any]:
        """The header attributes every complete frame of this identity carries."""
        return {"frame": self.frame, "look_hash": self.look_hash, "motion_hash": self.motion_hash}


def frame_identity(baked: BakedFrame, look: str, order: Order | None) -> FrameIdentity:
    """The identity of the frame rendered from `baked` with the look `look`: one walk of
    its motion (`frame_digests`), objects and lights by their place in `order`."""
    motion_hash, parts = frame_digests(baked, order)
    return FrameIdentity(baked.frame, look, motion_hash[:16], parts)


def header_attributes(ident: FrameIdentity, *, settings_hash: str, scene_hash: str, look_parts: str = "", files: str = "") -> dict[str, Any]:
    """The identity as a frame's header keeps it (`motion:<key>`): the record, the settings
    and scene hashes, the renderer's version, and to name what differs: the look's parts
    (`look_parts`, JSON), each moving thing's motion digest (when there are at most
    MAX_PARTS) and the digest of each file the scene names (`files`, JSON)."""
    return {
        **ident.expected(),
        "settings_hash": settings_hash,
        **({"look_parts": look_parts} if look_parts else {}),
        **({"motion_parts": json.dumps(dict(ident.motion_parts), sort_keys=True)} if len(ident.motion_parts) <= MAX_PARTS else {}),
        "scene_hash": scene_hash,
        "renderer": RENDERER_VERSION,
        **({"files": files} if files else {}),
    }


class WholeFrames:
    """Frame files found whole (every channel decoded), by their file's identity on disk:
    device, inode, size, modification and status-change times. A file none of whose five
    changed since it decoded whole holds the same bytes (a write, a truncation, a copy
    over it or a rename onto it changes its inode, size or times; the status-change time
    cannot be set back), so it is not decoded again: what git's index and a deliverable's
    manifest (shot/deliver.py) rely on. `known`: file name -> its five, as kept."""

    def __init__(self, known: Mapping[str, list[int]] | None = None) -> None:
        self.known = dict(known or {})
        self.found: dict[str, list[int]] = {}

    @staticmethod
    def _signature(path: str | Path) -> list[int] | None:
        try:
            st = os.stat(path)
        except OSError:
            return None
        return [st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns]

    def unchanged(self, path: str | Path) -> bool:
        """Whether the file at `path` is one known whole, unchanged since it decoded."""
        before = self._signature(path)
        return before is not None and self.known.get(Path(path).name) == before

    def is_whole(self, path: str | Path) -> bool:
        """Whether the EXR at `path` reads back whole: known so by its unchanged file, else
        decoded (frame_output.is_complete) and, when whole and unchanged meanwhile, noted."""
        name, before = Path(path).name, self._signature(path)
        if before is not None and self.known.get(name) == before:
            self.found[name] = before
            return True
        if not is_complete(path):
            return False
        if before is not None and self._signature(path) == before:
            self.found[name] = before
        return True


def frame_pixels_digest(path: str | Path) -> str:
    """The pixel digest of the EXR at `path`: the one its header records (written with the
    frame, no pixel decoded), or, for a frame written without one, computed from its decoded
    channels. FrameIOError for a file that does not read."""
    path = Path(path)
    header = read_header(path)
    recorded = header.get(META_PREFIX + PIXELS_KEY)
    if isinstance(recorded, str) and len(recorded) == 64 and all(c in "0123456789abcdef" for c in recorded):
        return recorded
    check_data_window(path, header)  # before a pixel is allocated
    import numpy as np
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return pixel_digest({name: np.asarray(ch.pixels) for name, ch in f.channels().items()})
    except Exception as exc:  # the bindings raise RuntimeError for any bad file
        raise FrameIOError(f"{path}: not a readable OpenEXR file ({exc})") from None


def complete_as(path: str | Path, expect: FrameIdentity, whole: WholeFrames | None = None, meta: Mapping[str, Any] | None = None) -> bool:
    """Whether the EXR at `path` reads back whole (every channel decoded, or known whole
    by `whole`) and its header carries the identity `expect`: what `--resume` keeps, and
    what a shipped frame must be before it is sent home. `meta`: its header's attributes
    when already read."""
    if meta is None:
        try:
            meta = read_meta(path)
        except FrameIOError:
            return False
    if not all(meta.get(k) == v for k, v in expect.expected().items()):
        return False
    return whole.is_whole(path) if whole is not None else is_complete(path)


def _stored_dict(stored: Any) -> dict[str, Any] | None:
    """A JSON object kept as a header attribute, or None (absent, not JSON, not an object)."""
    try:
        value = json.loads(stored) if isinstance(stored, str) else None
    except ValueError:
        return None
    return value if isinstance(value, dict) else None


def stored_parts(raw: Any) -> dict[str, str] | None:
    """The parts of a digest as a header keeps them (`look_parts`, `motion_parts`: JSON
    {part: digest}), or None when absent or not that: the one reader of them (reruns,
    compare)."""
    if not isinstance(raw, (str, bytes)):
        return None
    try:
        parts = json.loads(raw)
    except (ValueError, RecursionError):
        return None
    if not isinstance(parts, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in parts.items()):
        return None
    return parts


def settings_change(stored: Any, current: Mapping[str, Any]) -> str | None:
    """'spp 16 -> 4, resolution 320x180 -> 64x36' from the header's render settings (JSON)
    and this run's, or None when the header has none or they agree."""
    before = _stored_dict(stored)
    if before is None:
        return None

    def show(v: Any) -> str:
        if isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) for x in v):
            return f"{v[0]}x{v[1]}"
        return json.dumps(v) if not isinstance(v, str) else v

    now = json.loads(json.dumps(dict(current)))
    diffs = [f"{k} {show(before.get(k))} -> {show(now.get(k))}" for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k)]
    return ", ".join(diffs) if diffs else None


def files_change(stored: Any, current: Mapping[str, str] | None) -> str | None:
    """'tex.png changed, bump.png changed' from the header's file digests (JSON) and this
    run's (`render.job.file_digests`): files whose bytes changed under the same name, at
    most three named. None when the header has none, or none changed in place (a file
    added or dropped is an edit of the scene itself, named as such)."""
    before = _stored_dict(stored)
    if before is None or current is None:
        return None
    changes = [f"{k} changed" for k in sorted(before.keys() & current.keys()) if before[k] != current[k]]
    if not changes:
        return None
    return ", ".join(changes[:3]) + (f" and {len(changes) - 3} more" if len(changes) > 3 else "")


@dataclass(frozen=True)
class CurrentKeys:
    """This run's side of the comparison, to name what differs: the scene (its render
    settings are dumped only when a frame's look differs: `settings`), the file digests
    (`inputs.file_digests`), the look's parts (`look.look_parts`) and what each part is
    called in this scene (`look.part_names`); each frame's motion parts come with its
    `FrameIdentity`."""

    scene: Any
    files: Mapping[str, str] | None = None
    look_parts: Mapping[str, str] = field(default_factory=dict)
    names: Mapping[str, str] = field(default_factory=dict)

    @cached_property
    def settings(self) -> dict[str, Any]:
        """The scene's render settings as a header keeps them (`inputs.render_settings`)."""
        return render_settings(self.scene)


MAX_NAMED = 3  # things named in one reason; the rest are counted


def parts_change(stored: Any, current: Mapping[str, str], names: Mapping[str, str], prefix: str = "") -> list[str] | None:
    """The names of the parts whose digests differ between a header's (JSON) and this
    run's, in the order of `names` (a part this scene lacks by its label), or None when the
    header has none."""
    before = stored_parts(stored)
    if before is None or not current:
        return None
    differ = [p for p in sorted(set(before) | set(current)) if before.get(p) != current.get(p)]
    place = {name: i for i, name in enumerate(names)}
    differ.sort(key=lambda p: place.get(prefix + p, len(place)))
    return [names.get(prefix + p, f"{p} (no longer in the scene)" if p not in current else p) for p in differ]


def _listed(items: list[str]) -> str:
    """'a, b, c and 2 more'."""
    return ", ".join(items[:MAX_NAMED]) + (f" and {len(items) - MAX_NAMED} more" if len(items) > MAX_NAMED else "")


def reads_whole(path: str | Path) -> bool:
    """Whether the EXR at `path` is whole without decoding it all: OpenEXR's `isComplete`
    (every chunk the offset table names starts inside the file) and the file's last
    scanline chunk decoded, so a copy cut short anywhere is found. A chunk damaged in
    the middle is found only by decoding it (is_complete)."""
    import OpenEXR

    try:
        f = OpenEXR.InputFile(str(path))
    except Exception:  # the bindings raise their own error for any bad file
        return False
    try:
        header = f.header()
        last, channel = header["dataWindow"].max.y, next(iter(header["channels"]))
        return bool(f.isComplete()) and len(f.channel(channel, scanLine1=last, scanLine2=last)) > 0
    except Exception:  # a chunk that does not decode
        return False
    finally:
        f.close()


def why_stale(path: str, expect: FrameIdentity, now: CurrentKeys, decode: bool = True, whole: WholeFrames | None = None) -> str | None:
    """Why the frame at `path` is not a complete frame of this run, or None if it is.
    `decode=False`: a frame that `reads_whole` (its chunks all there, the last one
    decoded) counts as whole; for a run whose deliverables decode every frame next and
    name one that does not (`--check --deliver`: each frame decoded once). `whole`: the
    frames of its folder known whole (`WholeFrames`): the header of one of those, unchanged
    since it decoded, is read without the OpenEXR bindings (frame_output.plain_meta)."""
    meta = plain_meta(path) if whole is not None and whole.unchanged(path) else None
    if meta is None:
        try:
            meta = read_meta(path)
        except FrameIOError:
            return "do not read back as OpenEXR (incomplete or foreign)"
    if meta.get("look_hash") != expect.look_hash:
        change = settings_change(meta.get("render_settings"), now.settings)
        if change:
            return f"were made with other settings ({change})"
        edited = files_change(meta.get("files"), now.files)
        if edited:
            return f"were made from other files ({edited})"
        if "settings_hash" not in meta:
            return "were not made by motion render (no settings in the header)"
        if "look_hash" not in meta:
            return "were made by an earlier version of motion render (no frame key in the header)"
        parts = parts_change(meta.get("look_parts"), now.look_parts, now.names)
        if parts:
            return f"were made from another version of the scene ({_listed([p + ' changed' for p in parts])})"
        return "were made from another version of the scene or its settings"
    if meta.get("motion_hash") != expect.motion_hash:
        moved = parts_change(meta.get("motion_parts"), expect.motion_parts, now.names, MOVING)
        if moved:
            return f"were made from other motion (motion of {_listed(moved)} changed)"
        return "were made from other motion (the scene's animation or simulation changed)"
    if meta.get("frame") != expect.frame:
        return f"hold frame {meta.get('frame')}"
    if not (complete_as(path, expect, whole, meta) if decode else reads_whole(path)):
        return "do not read back whole (a truncated or damaged file)"
    return None


def recorded_keys(paths: Mapping[int, str], frames: list[int], settings_hash: str, look: str) -> dict[int, FrameIdentity] | None:
    """Each existing frame's identity as its header records it, when every one of them says
    it was made from this version: the same settings hash (the whole scene with every
    override and each file it names by its bytes, which the bake is a function of), look
    and renderer. Then the frames' motion is this run's motion and `--check` need not
    simulate and bake the shot again to know it (frame_states still reads each header and
    checks that the frame is whole). None when any frame says otherwise (or has no key):
    the run bakes, compares each frame's motion and names what changed."""
    out: dict[int, FrameIdentity] = {}
    for f in frames:
        if not os.path.exists(paths[f]):
            continue
        try:
            meta = read_meta(paths[f])
        except FrameIOError:
            return None
        if (meta.get("settings_hash"), meta.get("look_hash"), meta.get("renderer"), meta.get("frame")) != (settings_hash, look, RENDERER_VERSION, f) \
                or not isinstance(meta.get("motion_hash"), str):
            return None
        out[f] = FrameIdentity(f, look, meta["motion_hash"])
    return out
