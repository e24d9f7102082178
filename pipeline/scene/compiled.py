"""The validators of the scene format's root records, kept between processes.

pydantic makes the scene's validator from its ~75 record classes when a process first
validates a scene: it walks every field's annotation into a core schema (a large part of a
`motion validate`: docs/ci-sharding.md, "What validation keeps", has the figures), and
pydantic-core compiles that quickly. The core schema depends only on the record classes,
so the first process keeps it in the cache root (`validation/`, one entry per root record)
and later processes load it.

The entry is the validator pickled (pydantic-core pickles a validator as its core schema and
config; classes and validator functions by their import names), behind a list of the source
files of every `motion` module loaded when it was made, with their size and modification
time. An entry is used only if every one of those files is unchanged, and only by the same
Python, pydantic and pydantic-core; else, or if it cannot be read, the validator is made
again and the entry replaced. Its loss costs only that time (the `validators` store keeps
it best effort).

Unpickling can run code, so an entry is read only if it is ours (`cache.trusted`: a regular
file owned by this user and writable by nobody else, in folders from the cache root down
that are ours and writable by nobody else); one planted by another user who can write a
shared cache root is never opened (one warning line; the validator is made again), and it
is read bounded (a FIFO in its place is never waited on). Even then the unpickler resolves
only the names a validator needs (`_Unpickler.find_class`): the scene stage's record
classes, pydantic-core's SchemaValidator and an attribute lookup on those classes.
Rebuilding instead of keeping would cost that walk in every `motion validate`
(docs/ci-sharding.md, "Caches").
"""

from __future__ import annotations

import hashlib
import io
import pickle
import sys
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel
from pydantic_core import SchemaValidator

from ..cache import STORES

STORE = STORES["validators"]
FORMAT = 2  # of the entry; part of its name (2: read only when ours, names resolved by an allow-list)
MOST_BYTES = 16 << 20  # an entry is ~64 KB
_validators: dict[type[BaseModel], SchemaValidator] = {}
Stamp = tuple[str, int, int]  # a source file, its size and its modification time (ns)
M = TypeVar("M", bound=BaseModel)


def validate(cls: type[M], data: Any) -> M:
    """`cls.model_validate(data)` through the kept validator: the same records and the
    same `ValidationError`s."""
    return kept_validator(cls).validate_python(data)  # type: ignore[no-any-return]


def kept_validator(cls: type[BaseModel]) -> SchemaValidator:
    """The validator of a root record (the scene, the import list): this process's, else
    the cache root's, else made now (and kept)."""
    validator = _validators.get(cls)
    if validator is None:
        entry = entry_path(cls)
        validator = _load(entry, cls)
        if validator is None:
            validator = _made(cls)
            _keep(entry, validator)
        _validators[cls] = validator
    return validator


def entry_path(cls: type[BaseModel]) -> Path:
    """The cache entry of `cls` for this Python, pydantic, pydantic-core and installed tree."""
    import pydantic
    import pydantic_core

    key = "|".join((str(FORMAT), f"{cls.__module__}.{cls.__qualname__}", sys.version, pydantic.VERSION, pydantic_core.__version__, str(Path(__file__).resolve().parent)))
    return STORE.dir() / f"{cls.__name__}-{hashlib.sha256(key.encode()).hexdigest()[:16]}.pickle"


def _made(cls: type[BaseModel]) -> SchemaValidator:
    """The class's own validator, made by pydantic if it has not been yet."""
    cls.model_rebuild()  # a no-op when the class is already complete
    return cls.__pydantic_validator__  # type: ignore[return-value]


def _sources() -> list[Stamp]:
    """The source files of every loaded `motion` module, stamped."""
    out = []
    for name, module in list(sys.modules.items()):
        file = getattr(module, "__file__", None)
        if file and (name == "motion" or name.startswith("motion.")):
            stamp = _stamp(file)
            if stamp is not None:
                out.append(stamp)
    return sorted(out)


def _stamp(file: str) -> Stamp | None:
    try:
        st = Path(file).stat()
    except OSError:
        return None
    return (file, st.st_size, st.st_mtime_ns)


_SCENE_STAGE = "motion.pipeline.scene."
_HOOKS = ("__get_pydantic_json_schema__",)  # the one dunder pydantic-core looks up on a record class


def _attribute(owner: Any, name: str) -> Any:
    """`getattr` as a kept validator may use it: a validator function or hook of one of the
    scene stage's record classes, nothing else."""
    if not (isinstance(owner, type) and owner.__module__.startswith(_SCENE_STAGE)) or (name.startswith("__") and name not in _HOOKS):
        raise pickle.UnpicklingError(f"a kept validator may not look up {name!r} on {owner!r}")
    return getattr(owner, name)


class _Unpickler(pickle.Unpickler):
    """An unpickler that resolves only what a kept validator names (defence in depth: the
    entry was already found to be ours)."""

    def find_class(self, module: str, name: str) -> Any:
        """The scene stage's record classes and validator functions, pydantic-core's
        SchemaValidator, and `_attribute` for `builtins.getattr`; UnpicklingError otherwise."""
        if (module, name) == ("builtins", "getattr"):
            return _attribute
        if (module, name) == ("pydantic_core._pydantic_core", "SchemaValidator"):
            return SchemaValidator
        if module.startswith(_SCENE_STAGE) and not any(part.startswith("__") for part in name.split(".")):
            found = super().find_class(module, name)
            if getattr(found, "__module__", None) == module:  # defined there, not imported into it (a module, os.system)
                return found
        raise pickle.UnpicklingError(f"a kept validator may not name {module}.{name}")


def _load(entry: Path, cls: type[BaseModel] | None = None) -> SchemaValidator | None:
    """The kept validator if the entry is ours, reads whole, every source it names is
    unchanged and it validates `cls` (the root record of its core schema is that very
    class: an entry holding another class's validator would hand every later load records
    of the wrong kind); None otherwise (a foreign, damaged or mismatched entry says so in
    one warning line)."""
    data = STORE.read(entry, MOST_BYTES)
    if data is None:
        if entry.exists() or entry.is_symlink():
            _discard(entry, "not a regular file of ours that only we may write")
        return None
    try:
        unpickler = _Unpickler(io.BytesIO(data))
        sources = unpickler.load()
        if not isinstance(sources, list) or not sources or any(not isinstance(s, (list, tuple)) or len(s) != 3 or _stamp(str(s[0])) != tuple(s) for s in sources):
            return None
        validator = unpickler.load()
    except Exception as exc:  # truncated, naming a class the code no longer has, or a name it may not
        _discard(entry, f"{type(exc).__name__}")
        return None
    if not isinstance(validator, SchemaValidator):
        _discard(entry, f"a {type(validator).__name__}, not a validator")
        return None
    if cls is not None and _root_class(validator) is not cls:
        found = _root_class(validator)
        _discard(entry, f"it validates {getattr(found, '__qualname__', 'another record')}, not {cls.__qualname__}")
        return None
    return validator


def _root_class(validator: SchemaValidator) -> type | None:
    """The record class a validator's core schema validates at its root, through the
    record's own model validators wrapped around it (None when the root is not a model
    record): pydantic-core pickles a validator as (schema, config), so the schema is at
    hand without building one."""
    try:
        schema = validator.__reduce__()[1][0]
        for _ in range(8):  # definitions around a model, or a reference into them
            if not isinstance(schema, dict):
                return None
            kind = schema.get("type")
            if kind == "model":
                found = schema.get("cls")
                return found if isinstance(found, type) else None
            if kind in ("function-after", "function-before", "function-wrap"):  # a record's own model validator around it
                schema = schema.get("schema")
            elif kind == "definitions":
                definitions = {d.get("ref"): d for d in schema.get("definitions", []) if isinstance(d, dict)}
                schema = schema.get("schema")
                if isinstance(schema, dict) and schema.get("type") == "definitions-ref":
                    schema = definitions.get(schema.get("schema_ref"))
            else:
                return None
    except (AttributeError, IndexError, TypeError):
        return None
    return None


def _discard(entry: Path, why: str) -> None:
    import logging

    logging.getLogger("motion").warning(f"motion: warning: {entry}: kept validator discarded ({why}); it is made again")


def _keep(entry: Path, validator: SchemaValidator) -> None:
    """Write the entry (best effort). A validator pydantic wrapped for its plugins is not kept."""
    if type(validator) is not SchemaValidator:
        return

    buf = io.BytesIO()
    try:
        pickler = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
        pickler.dump(_sources())
        pickler.dump(validator)
    except Exception:  # a validator function pickle cannot name: keep nothing
        return
    STORE.put(entry, buf.getvalue(), best_effort=True, doing="keeping the scene's validator")
