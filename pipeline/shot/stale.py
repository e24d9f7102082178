"""Frames already on disk, before a run: complete (kept by --resume) or stale, and why;
and the frame files of a shot's output folder.

A frame is stale when its identity (identity/record.py: the look and its own baked motion)
differs from this run's, or it does not read back whole (docs/reruns.md). The run
replaces stale frames, and says so first, naming what differs (`spp 16 -> 4`, `material
iron changed`, `motion of box changed`), in the log, the dry run and the report: nothing
is replaced silently.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..farm.selection import format_frames
from ..identity import CurrentKeys, FrameIdentity, why_stale
from ..identity.record import WholeFrames


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


def frame_states(existing: list[int], paths: Mapping[int, str], expect: Mapping[int, FrameIdentity], now: CurrentKeys,
                 decode: bool = True, whole: WholeFrames | None = None) -> FrameStates:
    """Sort the selected frames found on disk into complete and stale (with the reason);
    `decode` and `whole` as why_stale's."""
    states = FrameStates()
    for f in existing:
        why = why_stale(paths[f], expect[f], now, decode, whole)
        if why is None:
            states.complete.append(f)
        else:
            states.stale[f] = why
    return states


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
    """The scene whose output folder `folder` is (its record, shot/folder_owner.py) and its
    frame files there, timeline and foreign apart: what `motion telecine` of a shot's
    folder takes, never mixing a render from before the timeline moved into its
    deliverable. None when the folder has no record, its scene file is gone or no longer
    loads, or `prefix` names another sequence than the scene's."""
    from ..errors import MotionError
    from ..scene.loader import load_scene
    from .folder_owner import recorded_scene

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
