"""Frames already on disk, before a run: complete (kept by --resume) or stale, and why.

A frame is stale when its header says it was made from another scene, motion or settings
than this run's (or it does not read back whole). The run replaces stale frames, and says
so first, naming the setting that differs (`spp 16 -> 4`), in the log, the dry run and the
report: nothing is replaced silently.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import FrameIOError
from ..farm.frames import format_frames
from ..frame_output import is_complete, read_meta


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


def why_stale(path: str, expect: Mapping[str, Any], settings: Mapping[str, Any], files: Mapping[str, str] | None = None) -> str | None:
    """Why the frame at `path` is not a complete frame of this run, or None if it is.
    `files`: this run's file digests, to name an asset that changed under the same name."""
    try:
        meta = read_meta(path)
    except FrameIOError:
        return "do not read back as OpenEXR (incomplete or foreign)"
    if meta.get("settings_hash") != expect.get("settings_hash"):
        change = settings_change(meta.get("render_settings"), settings)
        if change:
            return f"were made with other settings ({change})"
        edited = files_change(meta.get("files"), files)
        if edited:
            return f"were made from other files ({edited})"
        if "settings_hash" not in meta:
            return "were not made by motion render (no settings in the header)"
        return "were made from another version of the scene or its settings"
    if meta.get("motion_hash") != expect.get("motion_hash"):
        return "were made from other motion (the scene's animation or simulation changed)"
    if meta.get("frame") != expect.get("frame"):
        return f"hold frame {meta.get('frame')}"
    if not is_complete(path, expect):
        return "do not read back whole (a truncated or damaged file)"
    return None


def frame_states(existing: list[int], paths: Mapping[int, str], expect: Mapping[int, Mapping[str, Any]], settings: Mapping[str, Any],
                 files: Mapping[str, str] | None = None) -> FrameStates:
    """Sort the selected frames found on disk into complete and stale (with the reason)."""
    states = FrameStates()
    for f in existing:
        why = why_stale(paths[f], expect[f], settings, files)
        if why is None:
            states.complete.append(f)
        else:
            states.stale[f] = why
    return states
