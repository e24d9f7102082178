"""The records of a glTF or USD import, kept between loads.

An import's records depend only on the bytes of the files its reader reads (the .gltf or
.glb and the buffers and images it names; a USD stage's layers and the textures it
converts), the import entry without its overrides, where it is shown, the scene's folder
(a USD stage's layers are confined to it) and the readers' code. They are kept as one JSON
file in the import cache, beside the converted meshes, textures and skins they name, with
the digest of every file the reader read (`scene/files.digests_recorded`). A later load checks
those digests and that every converted file is still there, and then never imports the
reader: numpy and pygltflib, or usd-core (their import times: docs/imports.md). Any
difference, or an entry that does not read whole, and the file is read again.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ...cache import STORES, code_digest, trusted
from ...errors import InputFileError
from ..files import bytes_digest, digests_recorded, file_digest
from ...limits import MAX_GLTF_BYTES, MAX_RECORD_BYTES, MAX_USD_LAYER_BYTES, read_bounded, read_json_record
from .expansion import Expansion, Origin

STORE = STORES["import-records"]

# each reader's code is part of the key: a changed reader rebuilds
READERS = {"gltf": ("gltf.py", "expansion.py", "converted.py", "memo.py"), "usd": ("usd.py", "gltf.py", "expansion.py", "converted.py", "memo.py")}
FORMAT = 3  # of an entry: 2 adds the digests of the files read; 3 the file's suffix in the key
# no file larger than its reader accepts is hashed here (the reader refuses it unread)
MOST_BYTES = {"gltf": MAX_GLTF_BYTES, "usd": MAX_USD_LAYER_BYTES}


def read_import(path: Path, shown: str, spec: Any, index: int, base_dir: Path) -> Expansion:
    """The records of one glTF or USD import: kept ones when current, else the reader's (and
    kept); ImportFileError (the file and node or prim) or SpecError (the import entry's
    field) otherwise."""
    from .converted import STATS

    kind = "gltf" if path.suffix.lower() in (".gltf", ".glb") else "usd"
    if path.stat().st_size > MOST_BYTES[kind]:
        return _read_file(kind, path, shown, spec, index, base_dir)  # it says why not
    # the entry without its overrides, as text: its repr names every field's value (a dump
    # would build the entry's serializer, 0.01 s, for a key)
    settings = repr(spec.model_copy(update={"overrides": {}}))
    where = (kind, path.suffix.lower(), settings, shown, index, str(base_dir.resolve()))
    digest = file_digest(path)
    memo = _entry(where, digest)
    kept = _recall(memo, MOST_BYTES[kind], base_dir)
    if kept is not None:
        STATS["records"] += 1
        return kept
    raw: bytes | None = None
    if kind == "gltf":
        # read once: the records are parsed from the bytes their key is hashed from (a file
        # swapped between a hash and a read left one file's records under another's digest)
        try:
            raw = read_bounded(path, MOST_BYTES[kind], "glTF file")
        except InputFileError:
            return _read_file(kind, path, shown, spec, index, base_dir)  # it says why, located
        read_digest = bytes_digest(raw)
        if read_digest != digest:  # changed since it was hashed: kept under the bytes read
            digest, memo = read_digest, _entry(where, read_digest)
    with digests_recorded() as read:
        ex = _read_file(kind, path, shown, spec, index, base_dir, raw)
    read.pop(str(path.resolve()), None)  # the key has it
    parsed = {} if raw is not None else {str(path.resolve()): digest}  # (the glTF's own bytes were the ones hashed)
    if _unchanged({**parsed, **read}):  # else a file changed while it was read: its records are not kept
        STORE.put(memo, json.dumps({"read": read, "records": _to_json(ex)}).encode(), best_effort=True, doing="keeping an import's records")
    return ex


def _entry(where: tuple[Any, ...], digest: str) -> Path:
    """The kept records' file for an import `where` (the reader's kind and the suffix it
    goes by, the entry without its overrides, where it is shown, the scene's folder) of
    the bytes of `digest`, by the reader's code: everything that decides the records."""
    kind, suffix, settings, shown, index, base = where
    key = STORE.key(json.dumps([FORMAT, kind, suffix, digest, settings, shown, index, base, _code(kind)]))
    return STORE.path(key, "records", ".json")


def _unchanged(read: dict[str, str]) -> bool:
    """Whether every file still hashes as it did when its reader was given it (hashed
    afresh, not from the per-process memo): a file swapped between its hash and its read
    would otherwise keep another file's records under its key."""
    for file, digest in read.items():
        try:
            if file_digest(Path(file), memo=False) != digest:
                return False
        except OSError:
            return False
    return True


def _read_file(kind: str, path: Path, shown: str, spec: Any, index: int, base_dir: Path, raw: bytes | None = None) -> Expansion:
    """The reader's records (gltf.py, usd.py: numpy and pygltflib, or usd-core); a glTF
    parsed from `raw`, its bytes as hashed, when given."""
    if kind == "gltf":
        from .gltf import expand_gltf

        return expand_gltf(path, shown, spec, index, raw)
    from .usd import read_usd

    return read_usd(path, shown, spec, index, root=base_dir)


def _code(kind: str) -> str:
    """The reader's code version (cache.py's one code digest over its source files)."""
    return code_digest(tuple(f"scene/imports/{name}" for name in READERS[kind]))


def _recall(memo: Path, most_bytes: int, base_dir: Path) -> Expansion | None:
    """The kept records if the entry is ours (`cache.trusted`: another user's planted
    records are never read) and reads whole as a record, every file the reader read has the
    bytes it had (at the same place: a link put on its way since is a difference; grown past
    `most_bytes`, it is not hashed) and every converted file the records name is there. A
    damaged entry (not JSON, nested too deep, not a mapping, a FIFO; a record that is not a
    mapping, a name that is not text, a file named outside the scene's folder `base_dir`
    and the import cache) is one warning line and is made again."""
    if trusted(memo) is None:
        if memo.exists() or memo.is_symlink():
            STORE.stats["refused"] += 1
        return None
    doc = read_json_record(memo, "kept import records", limit=MAX_RECORD_BYTES)
    if doc is None:
        return None
    try:
        for file, digest in doc["read"].items():
            dep = Path(file)
            if dep.resolve() != dep or not dep.is_file() or dep.stat().st_size > most_bytes or file_digest(dep) != digest:
                return None
        ex = _from_json(doc["records"])
        records = [r for r, _ in ex.objects + ex.materials + ex.lights] + [r for _, r, _ in ex.cameras]
        why = _malformed(ex, records) or _outside(_files(records), base_dir)
        if why:
            raise ValueError(why)
    except OSError:
        return None
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        import logging

        logging.getLogger("motion").warning(f"motion: warning: {memo}: kept import records discarded (not the record expected: {exc if type(exc) is ValueError else type(exc).__name__}); they are made again")
        return None
    return ex if all(Path(f).is_file() for f in _files(records)) else None


def _malformed(ex: Expansion, records: list[Any]) -> str | None:
    """Why kept records are not records a reader makes (None when they are): each one a
    mapping with text keys, its name (and a camera's node name) text."""
    for rec in records:
        if not isinstance(rec, dict) or not all(isinstance(k, str) for k in rec):
            return f"a record is a {type(rec).__name__}, not a mapping"
        if "name" in rec and not isinstance(rec["name"], str):
            return f"a record's name is a {type(rec['name']).__name__}, not text"
    if not all(isinstance(name, str) for name, _, _ in ex.cameras):
        return "a camera's node name is not text"
    return None


def _outside(files: list[str], base_dir: Path) -> str | None:
    """The first file named outside the scene's folder tree and the import cache, as a
    reason (None when every one is inside): kept records may name only files the scene could
    name itself or files the readers converted."""
    from .converted import cache_dir

    roots = (base_dir.resolve(), cache_dir().resolve())
    for f in files:
        real = Path(f).resolve()
        if not any(real == root or real.is_relative_to(root) for root in roots):
            return f"a record names {f}, outside the scene's folder and the import cache"
    return None


def _files(value: Any) -> list[str]:
    """Every `file` value in a record (meshes, targets, skins, textures)."""
    if isinstance(value, dict):
        return [v for k, v in value.items() if k == "file" and isinstance(v, str)] + [f for v in value.values() for f in _files(v)]
    if isinstance(value, list):
        return [f for v in value for f in _files(v)]
    return []


def _to_json(ex: Expansion) -> dict[str, Any]:
    pack = lambda o: {"file": o.file, "where": o.where, "yaml_keys": o.yaml_keys, "default": o.default}  # noqa: E731
    return {
        "objects": [[r, pack(o)] for r, o in ex.objects],
        "materials": [[r, pack(o)] for r, o in ex.materials],
        "lights": [[r, pack(o)] for r, o in ex.lights],
        "cameras": [[n, r, pack(o)] for n, r, o in ex.cameras],
    }


def _from_json(doc: dict[str, Any]) -> Expansion:
    unpack = lambda d: Origin(d["file"], d["where"], {k: tuple(v) for k, v in d["yaml_keys"].items()}, tuple(d["default"]) if d["default"] is not None else None)  # noqa: E731
    return Expansion(
        objects=[(r, unpack(o)) for r, o in doc["objects"]],
        materials=[(r, unpack(o)) for r, o in doc["materials"]],
        lights=[(r, unpack(o)) for r, o in doc["lights"]],
        cameras=[(n, r, unpack(o)) for n, r, o in doc["cameras"]],
    )
