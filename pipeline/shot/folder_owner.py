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
import logging
import os
import stat
from pathlib import Path

from ..errors import InputFileError, ShotFolderTakenError, UsageError
from ..write_policy import write_atomic
from ..limits import read_bounded, read_json_record
from ..render.worker.job import scene_reference

RECORD = ".motion-shot.json"
RECORD_BYTES = 64 * 1024  # the record is one short path; more is not ours
WHAT = "the output folder's record of its scene file"


def recorded_scene(out_dir: Path, warn: bool = True) -> Path | None:
    """The scene file the folder's record names (absolute), or None when there is no
    usable record. A damaged one (not a regular file: a FIFO is never waited on; over its
    size; not JSON; not a mapping; a scene path that is empty, holds a NUL, or is longer
    than a path can be) is one warning line (`warn`), and the run writes it again."""
    path = out_dir / RECORD
    if warn:
        data = read_json_record(path, WHAT, dict, limit=RECORD_BYTES)
    else:
        try:
            data = json.loads(read_bounded(path, RECORD_BYTES, WHAT))
        except (InputFileError, ValueError, RecursionError):
            data = None
    if data is None:
        return None
    scene = data.get("scene") if isinstance(data, dict) else None
    why = _unusable(scene)
    if why:
        if warn:
            logging.getLogger("motion").warning(f"motion: warning: {path}: {WHAT} discarded ({why}); it is made again")
        return None
    return Path(os.path.normpath(out_dir / scene))


def _unusable(scene: object) -> str | None:
    """Why a record's scene value cannot name a file (None when it can)."""
    if not isinstance(scene, str) or not scene:
        return "no scene path"
    if "\0" in scene:
        return "its scene path holds a NUL"
    try:
        encoded = os.fsencode(scene)
    except UnicodeError:
        return "its scene path is not text a path can hold"
    if len(encoded) >= 4096 or any(len(part) > 255 for part in encoded.split(b"/")):
        return f"its scene path is {len(encoded)} bytes, longer than a path can be"
    return None


def _same_file(a: Path, b: Path) -> bool:
    """The two paths name one file (links followed), or the same path when either is gone."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return os.path.realpath(a) == os.path.realpath(b)


def check_owner(out_dir: Path, scene: Path, overwrite: bool) -> Path | None:
    """Refuse a folder whose record names another scene file that still exists, unless
    `overwrite`. Returns the other scene file when it is taken over (None otherwise). A
    folder where the record belongs is refused (UsageError): it is not ours to remove."""
    _refuse_folder(out_dir)
    owner = recorded_scene(out_dir)
    if owner is None or _same_file(owner, scene):
        return None
    if not os.path.isfile(owner):
        return owner  # gone (renamed, moved), or not a scene file at all
    if overwrite:
        return owner
    raise ShotFolderTakenError(
        f"{out_dir} holds the frames of {owner}, not of {scene} (both scenes are named the same): "
        f"give this one its own folder (-o DIR or output.directory), or --overwrite to replace that scene's frames"
    )


def record_owner(out_dir: Path, scene: Path) -> None:
    """Write the folder's record naming `scene` (atomically, through write_policy.py), unless it
    already does."""
    _refuse_folder(out_dir)
    owner = recorded_scene(out_dir, warn=False)
    if owner is not None and _same_file(owner, scene):
        return
    reference = scene_reference(scene, out_dir / "frame")
    write_atomic(out_dir / RECORD, (json.dumps({"scene": reference}, indent=2) + "\n").encode(), "writing the output folder's record")


def _refuse_folder(out_dir: Path) -> None:
    """UsageError when a folder stands where the record belongs (a FIFO, a link or another
    non-folder is replaced by the record's atomic rename; a folder cannot be, and may hold
    someone's files)."""
    try:
        mode = os.lstat(out_dir / RECORD).st_mode
    except (OSError, ValueError):
        return
    if stat.S_ISDIR(mode):
        raise UsageError(f"{out_dir / RECORD}: a folder stands where motion keeps {WHAT} (a small file): move it away or remove it, then run again")
