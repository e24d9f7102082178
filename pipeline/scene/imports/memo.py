"""The records of a glTF import, kept between loads (issue 28).

A glTF import's records depend only on its source files' bytes (the .gltf or .glb and the
buffers and images it names), the import entry without its overrides, where it is shown,
and the reader's code. They are kept as one JSON file in the import cache, beside the
converted meshes, textures and skins they name. A warm load reads that file and never
imports the reader (numpy and pygltflib, about 0.05 s of `motion validate`), as long as
every converted file it names is still there; otherwise the file is read again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from .cache import source_digest
from .records import Expansion, Origin

READER = Path(__file__).with_name("gltf.py")  # its code is part of the key: a changed reader rebuilds


def read_gltf(path: Path, shown: str, spec: Any, index: int) -> Expansion:
    """The records of one glTF import: kept ones when current, else `gltf.expand_gltf`'s
    (and kept); ImportFileError (the file and node) or SpecError (the import entry's field)
    otherwise."""
    from .cache import STATS, cache_dir, write_atomic

    # the entry without its overrides, as text: its repr names every field's value (a dump
    # would build the entry's serializer, 0.01 s, for a key)
    settings = repr(spec.model_copy(update={"overrides": {}}))
    code = hashlib.sha256(READER.read_bytes()).hexdigest()
    key = hashlib.sha256(json.dumps([source_digest(path), settings, shown, index, code]).encode()).hexdigest()[:32]
    memo = cache_dir() / f"records-{key}.json"
    if memo.is_file():
        try:
            ex = _from_json(json.loads(memo.read_text()))
            records = [r for r, _ in ex.objects + ex.materials + ex.lights]
            if all(Path(f).is_file() for f in _files(records)):
                STATS["records"] += 1
                return ex
        except (OSError, ValueError, KeyError, TypeError):
            pass  # rebuilt below
    from .gltf import expand_gltf

    ex = expand_gltf(path, shown, spec, index)
    write_atomic(memo, lambda tmp: tmp.write_text(json.dumps(_to_json(ex))))
    return ex


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
