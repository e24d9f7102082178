"""Frames already on disk, before a run: complete (kept by --resume) or stale, and why.

A frame is stale when what it shows can have changed (docs/reruns.md): its key in the
header, the look (the scene's content and render settings and the files it reads, names
left out: render/look.py) and its own baked motion (objects, lights and camera over its
shutter, by their place in the scene: bake/fingerprint.py), differs from this run's, or it
does not read back whole. A key moved outside a frame's shutter, a name or a comment keeps
it. The run replaces stale frames, and says so first, naming what differs (`spp 16 -> 4`,
`material iron changed`, `motion of box changed`), in the log, the dry run and the report:
nothing is replaced silently.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..errors import FrameIOError
from ..farm.selection import format_frames
from ..frame_output import is_complete, read_meta
from ..render.look import MOVING


@dataclass
class FrameStates:
    """The selected frames already on disk: those complete for this run, and the stale
    ones (frame -> why) that this run replaces."""

    complete: list[int] = field(default_factory=list)
    stale: dict[int, str] = field(default_factory=dict)

    def describe(self) -> list[str]:
        """One line per reason: which frames are replaced and why."""
        by_reason: dict[str, list[int]] = {}
        for f, why in sorted(self.stale.items()):
            by_reason.setdefault(why, []).append(f)
        return [f"frames {format_frames(fs)} exist but {why}: they will be replaced" if why != "--overwrite"
                else f"frames {format_frames(fs)} exist: --overwrite replaces them" for why, fs in by_reason.items()]


def _stored_dict(stored: Any) -> dict[str, Any] | None:
    """A JSON object kept as a header attribute, or None (absent, not JSON, not an object)."""
    try:
        value = json.loads(stored) if isinstance(stored, str) else None
    except ValueError:
        return None
    return value if isinstance(value, dict) else None


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
    """This run's side of the comparison, to name what differs: the render settings, the
    file digests (`render.job.file_digests`), the look's parts (`render.look.look_parts`),
    each frame's motion parts (`render.job.frame_key`) and what each part is called in
    this scene (`render.look.part_names`)."""

    settings: Mapping[str, Any]
    files: Mapping[str, str] | None = None
    look_parts: Mapping[str, str] = field(default_factory=dict)
    motion_parts: Mapping[int, Mapping[str, str]] = field(default_factory=dict)
    names: Mapping[str, str] = field(default_factory=dict)


MAX_NAMED = 3  # things named in one reason; the rest are counted


def parts_change(stored: Any, current: Mapping[str, str], names: Mapping[str, str], prefix: str = "") -> list[str] | None:
    """The names of the parts whose digests differ between a header's (JSON) and this
    run's, in the order of `names` (a part this scene lacks by its label), or None when the
    header has none."""
    before = _stored_dict(stored)
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


def why_stale(path: str, expect: Mapping[str, Any], now: CurrentKeys, decode: bool = True) -> str | None:
    """Why the frame at `path` is not a complete frame of this run, or None if it is.
    `decode=False`: a frame that `reads_whole` (its chunks all there, the last one
    decoded) counts as whole; for a run whose deliverables decode every frame next and
    name one that does not (`--check --deliver`: each frame decoded once)."""
    try:
        meta = read_meta(path)
    except FrameIOError:
        return "do not read back as OpenEXR (incomplete or foreign)"
    if meta.get("look_hash") != expect.get("look_hash"):
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
    if meta.get("motion_hash") != expect.get("motion_hash"):
        moved = parts_change(meta.get("motion_parts"), now.motion_parts.get(int(expect.get("frame", -1)), {}), now.names, MOVING)
        if moved:
            return f"were made from other motion (motion of {_listed(moved)} changed)"
        return "were made from other motion (the scene's animation or simulation changed)"
    if meta.get("frame") != expect.get("frame"):
        return f"hold frame {meta.get('frame')}"
    if not (is_complete(path, expect) if decode else reads_whole(path)):
        return "do not read back whole (a truncated or damaged file)"
    return None


def frame_states(existing: list[int], paths: Mapping[int, str], expect: Mapping[int, Mapping[str, Any]], now: CurrentKeys,
                 decode: bool = True) -> FrameStates:
    """Sort the selected frames found on disk into complete and stale (with the reason);
    `decode` as why_stale's."""
    states = FrameStates()
    for f in existing:
        why = why_stale(paths[f], expect[f], now, decode)
        if why is None:
            states.complete.append(f)
        else:
            states.stale[f] = why
    return states


def recorded_keys(paths: Mapping[int, str], frames: list[int], settings_hash: str, look: str, renderer: str) -> dict[int, dict[str, Any]] | None:
    """Each existing frame's key as its header records it, when every one of them says it
    was made from this version: the same settings hash (the whole scene with every
    override and each file it names by its bytes, which the bake is a function of), look
    and renderer. Then the frames' motion is this run's motion and `--check` need not
    simulate and bake the shot again to know it (frame_states still reads each header and
    checks that the frame is whole). None when any frame says otherwise (or has no key):
    the run bakes, compares each frame's motion and names what changed."""
    out: dict[int, dict[str, Any]] = {}
    for f in frames:
        if not os.path.exists(paths[f]):
            continue
        try:
            meta = read_meta(paths[f])
        except FrameIOError:
            return None
        if (meta.get("settings_hash"), meta.get("look_hash"), meta.get("renderer"), meta.get("frame")) != (settings_hash, look, renderer, f) \
                or not isinstance(meta.get("motion_hash"), str):
            return None
        out[f] = {"frame": f, "look_hash": look, "motion_hash": meta["motion_hash"]}
    return out


@dataclass(frozen=True)
class FolderFrames:
    """The frame files of a scene in its output folder (by the scene's own file naming):
    those of its timeline, and the foreign ones outside it (a render from before the
    timeline moved, `first: 1001` after keys written at 0-23) that a run leaves alone and
    no deliverable takes."""

    timeline: dict[int, Path] = field(default_factory=dict)
    foreign: dict[int, Path] = field(default_factory=dict)


def folder_frames(out_dir: Path, loaded: Any) -> FolderFrames:
    """The frame files named as `loaded` names its frames in `out_dir`, split into those
    of its timeline (first..last) and the foreign ones. A name whose frame number sits in
    a folder part of `output.filename` is not looked for (nothing is found)."""
    scene = loaded.scene
    pattern = scene.output.filename.replace("{name}", loaded.name)
    folder, name = (out_dir / pattern).parent, Path(pattern).name
    run = re.search(r"#+", name)
    if run is None or not folder.is_dir():
        return FolderFrames()
    number = re.compile(re.escape(name[: run.start()]) + r"(-?\d+)" + re.escape(name[run.end():]) + r"\Z")
    out = FolderFrames()
    first, last = scene.timeline.first, scene.timeline.last
    for path in folder.iterdir():
        m = number.match(path.name)
        if m is None or not path.is_file():
            continue
        frame = int(m.group(1))
        (out.timeline if first <= frame <= last else out.foreign)[frame] = path
    return out


def shot_folder_frames(folder: Path, prefix: str | None = None) -> tuple[Any, FolderFrames] | None:
    """The scene whose output folder `folder` is (its record, shot/identity.py) and its
    frame files there, timeline and foreign apart: what `motion telecine` of a shot's
    folder takes, never mixing a render from before the timeline moved into its
    deliverable. None when the folder has no record, its scene file is gone or no longer
    loads, or `prefix` names another sequence than the scene's."""
    from ..errors import MotionError
    from ..scene.loader import load_scene
    from .identity import recorded_scene

    scene = recorded_scene(folder)
    if scene is None or not scene.is_file():
        return None
    try:
        loaded = load_scene(scene, assets=False)
    except MotionError:  # an edited scene that no longer validates: the folder is read as it is
        return None
    found = folder_frames(folder, loaded)
    names = {p.name.rsplit(".", 2)[0] for p in [*found.timeline.values(), *found.foreign.values()]}
    if prefix is not None and names != {prefix}:
        return None
    return loaded, found
