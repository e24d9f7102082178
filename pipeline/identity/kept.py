"""Each frame's identity kept in the cache layer (`cache.STORES["frame-keys"]`), so that a
rerun that renders nothing knows every frame's identity without simulating or baking the
shot again (docs/identity.md, "Kept identities").

A frame's identity is a function of the validated scene with every override and every file
it names by its bytes (the settings digest, identity/inputs.py), the frame's number and the
code that simulates, evaluates, bakes and digests the motion and makes the look. An entry
is keyed by exactly these: the settings digest and the version of that code and of the
installed numpy, scipy and pydantic (`code_version`). It holds the look's parts and, per frame, the motion
digest and its parts, as JSON; a run that bakes adds the frames it baked. An entry that is
not ours, over its bound, or not of the format is not believed: the run bakes as if there
were none, and writes it again.
"""

from __future__ import annotations

import hashlib
import json
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..cache import STORES, Store, file_stamp, package_file
from .record import FrameIdentity, WholeFrames

log = logging.getLogger("motion")

STORE: Store = STORES["frame-keys"]
FORMAT = "motion-frame-keys/1"
MAX_BYTES = 64 << 20  # one entry: 1,024 parts of 30 bytes for each of 2,000 frames
# the code a kept identity depends on: the simulation's (bake/keep.py) and the bake's, the
# identity's own, and what the look reads beside the scene's records
_CODE_FOLDERS = ("bake", "identity")
_CODE_FILES = ("render/translate/roles.py", "scene/files.py", "scene/lights.py")
_LIBRARIES = ("numpy", "scipy", "pydantic")  # the look's parts are pydantic's JSON dumps
_HEX16 = re.compile(r"[0-9a-f]{16}\Z")
_code_version: str | None = None


def code_version() -> str:
    """The version of the code a frame's identity comes from (`_CODE_FOLDERS`,
    `_CODE_FILES` and the simulation's `bake.keep.CODE_FOLDERS` and `CODE_FILES`, and the
    installed numpy, scipy and pydantic), by each source file's path, size and modification
    time: what Python itself checks before it runs a module's cached bytecode, so any code
    that would run differently is another version; read in a few stats, not by hashing
    every file."""
    global _code_version
    if _code_version is None:
        from ..bake.keep import CODE_FILES, CODE_FOLDERS

        source = Path(__file__).resolve().parents[1]
        files = sorted({p for folder in (*CODE_FOLDERS, *_CODE_FOLDERS) for p in (source / folder).glob("*.py")} |
                       {source / name for name in (*CODE_FILES, *_CODE_FILES)})
        files += [p for p in map(package_file, _LIBRARIES) if p is not None]
        _code_version = hashlib.sha256("\n".join(map(file_stamp, files)).encode()).hexdigest()
    return _code_version


@dataclass
class KeptKeys:
    """What the cache holds for one settings digest: where (`entry`), the look's parts
    (None when nothing is kept) and each frame's identity kept so far."""

    entry: Path
    look_parts: dict[str, str] | None = None
    frames: dict[int, FrameIdentity] = field(default_factory=dict)


def _hex_parts(value: Any) -> dict[str, str] | None:
    """{part: 16 hex digits} as kept, or None when it is not that."""
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) and _HEX16.match(v) for k, v in value.items()):
        return None
    return value


def _parse(data: bytes, entry: Path) -> KeptKeys | None:
    """The entry's record, or None when it is not one of the format."""
    try:
        doc = json.loads(data)
    except (ValueError, RecursionError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("frames"), dict):
        return None
    look_parts, look = _hex_parts(doc.get("look_parts")), doc.get("look_hash")
    if look_parts is None or not isinstance(look, str) or not _HEX16.match(look):
        return None
    frames: dict[int, FrameIdentity] = {}
    for number, kept in doc["frames"].items():
        if not re.fullmatch(r"-?\d{1,10}", number) or not isinstance(kept, dict):
            return None
        motion, parts = kept.get("motion_hash"), _hex_parts(kept.get("motion_parts"))
        if not isinstance(motion, str) or not _HEX16.match(motion) or parts is None:
            return None
        frames[int(number)] = FrameIdentity(int(number), look, motion, parts)
    return KeptKeys(entry, look_parts, frames)


def kept_keys(settings_digest: str) -> KeptKeys:
    """What the cache keeps for the scene whose settings digest is `settings_digest`
    (nothing: `look_parts` None and no frames)."""
    entry = STORE.path(STORE.key(code_version(), settings_digest), stem="keys", suffix=".json")
    data = STORE.read(entry, MAX_BYTES)
    kept = _parse(data, entry) if data is not None else None
    if kept is None:
        if data is not None:
            log.warning(f"motion: warning: the kept frame identities {entry} are damaged: discarded, baking again")
            STORE.stats["refused"] += 1
        STORE.stats["misses"] += 1
        return KeptKeys(entry)
    STORE.stats["hits"] += 1
    return kept


def keep_keys(kept: KeptKeys, look_parts: Mapping[str, str], look: str, frames: Mapping[int, FrameIdentity]) -> None:
    """Keep the look's parts and the identities of `frames` (with those kept before under
    the same entry) for the next run; best effort: a disk that refuses it costs only the
    next run's bake."""
    merged = {**(kept.frames if kept.look_parts == dict(look_parts) else {}), **frames}
    doc = {"format": FORMAT, "look_hash": look, "look_parts": dict(look_parts),
           "frames": {str(n): {"motion_hash": i.motion_hash, "motion_parts": dict(i.motion_parts)} for n, i in sorted(merged.items())}}
    data = json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()
    if len(data) <= MAX_BYTES:
        STORE.put(kept.entry, data, best_effort=True, doing="keeping the frames' identities")
        kept.look_parts, kept.frames = dict(look_parts), merged


MAX_WHOLE_BYTES = 16 << 20  # one folder's record: about 100 bytes a frame


def _whole_entry(folder: Path) -> Path:
    """Where the record of the frames found whole in `folder` (by its real path) lives."""
    return STORE.path(STORE.key("whole", str(Path(folder).resolve())), stem="whole", suffix=".json")


def whole_frames(folder: Path) -> WholeFrames:
    """The frame files of `folder` found whole by an earlier run, by their file's identity
    on disk (record.WholeFrames); none when the record is missing, not ours or not of the
    format."""
    data = STORE.read(_whole_entry(folder), MAX_WHOLE_BYTES)
    try:
        doc = json.loads(data) if data is not None else None
    except (ValueError, RecursionError):
        doc = None
    known = doc.get("frames") if isinstance(doc, dict) and doc.get("format") == FORMAT else None
    if not isinstance(known, dict):
        return WholeFrames()
    return WholeFrames({k: v for k, v in known.items() if isinstance(k, str) and isinstance(v, list) and len(v) == 5 and all(type(x) is int for x in v)})


def keep_whole(folder: Path, whole: WholeFrames) -> None:
    """Keep the frames found whole in this run (only those: a frame gone or replaced drops
    out) for the next; best effort, and nothing written when the record would not change."""
    if whole.found == whole.known:
        return
    data = json.dumps({"format": FORMAT, "frames": whole.found}, sort_keys=True, separators=(",", ":")).encode()
    if len(data) <= MAX_WHOLE_BYTES:
        STORE.put(_whole_entry(folder), data, best_effort=True, doing="keeping which frames read back whole")
