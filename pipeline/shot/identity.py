"""Which scene file an output folder belongs to (docs/reruns.md).

Two scene files with the same `name:` share `out/<name>`: each run replaced the other's
frames as "made with other settings". The folder keeps one small record, RECORD, naming
the scene file that renders into it (relative to the folder when the two share a project
tree, as a frame's header names it, so a tree that moves as a whole keeps its folders).
A run of another scene file is refused with one line naming both, before any frame; with
`--overwrite` it takes the folder over. A scene file that is no longer there (renamed,
moved) leaves its folder to the one that renders into it now: two files cannot compete
for it then.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import ShotFolderTakenError
from ..files import write_atomic
from ..render.job import scene_reference

RECORD = ".motion-shot.json"


def recorded_scene(out_dir: Path) -> Path | None:
    """The scene file the folder's record names (absolute), or None when there is no
    readable record."""
    try:
        data = json.loads((out_dir / RECORD).read_text())
    except (OSError, ValueError):
        return None
    scene = data.get("scene") if isinstance(data, dict) else None
    if not isinstance(scene, str) or not scene:
        return None
    return Path(os.path.normpath(out_dir / scene))


def _same_file(a: Path, b: Path) -> bool:
    """The two paths name one file (links followed), or the same path when either is gone."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_owner(out_dir: Path, scene: Path, overwrite: bool) -> Path | None:
    """Refuse a folder whose record names another scene file that still exists, unless
    `overwrite`. Returns the other scene file when it is taken over (None otherwise)."""
    owner = recorded_scene(out_dir)
    if owner is None or _same_file(owner, scene):
        return None
    if not owner.exists():
        return owner
    if overwrite:
        return owner
    raise ShotFolderTakenError(
        f"{out_dir} holds the frames of {owner}, not of {scene} (both scenes are named the same): "
        f"give this one its own folder (-o DIR or output.directory), or --overwrite to replace that scene's frames"
    )


def record_owner(out_dir: Path, scene: Path) -> None:
    """Write the folder's record naming `scene` (atomically, through files.py), unless it
    already does."""
    owner = recorded_scene(out_dir)
    if owner is not None and _same_file(owner, scene):
        return
    reference = scene_reference(scene, out_dir / "frame")
    write_atomic(out_dir / RECORD, (json.dumps({"scene": reference}, indent=2) + "\n").encode(), "writing the output folder's record")
