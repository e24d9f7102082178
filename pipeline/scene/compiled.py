"""The validators of the scene format's root records, kept between processes (issue 28).

pydantic makes the scene's validator from its ~75 record classes when a process first
validates a scene: it walks every field's annotation into a core schema (about 0.035 s on
the 2-core bench machine, a fifth of `motion validate`; 0.017 s for the `imports:` list),
and pydantic-core compiles that in well under a millisecond. The core schema depends only
on the record classes, so the first process keeps it in the cache root (`validation/`,
one entry per root record) and later processes load it (about 1 ms).

The entry is the validator pickled (pydantic-core pickles a validator as its core schema and
config; classes and validator functions by their import names), behind a list of the source
files of every `motion` module loaded when it was made, with their size and modification
time. An entry is used only if every one of those files is unchanged, and only by the same
Python, pydantic and pydantic-core; else, or if it cannot be read, the validator is made
again and the entry replaced. Its loss costs only that time (`files.write_best_effort`).
The cache root is the user's own, like drjit's kernel cache beside it: an entry is trusted
as code, as those kernels are.
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

from ..cache import validation_dir

FORMAT = 1  # of the entry; part of its name
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
        validator = _load(entry)
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
    return validation_dir() / f"{cls.__name__}-{hashlib.sha256(key.encode()).hexdigest()[:16]}.pickle"


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


def _load(entry: Path) -> SchemaValidator | None:
    """The kept validator if the entry reads whole and every source it names is unchanged."""
    try:
        with open(entry, "rb") as fh:
            unpickler = pickle.Unpickler(fh)
            sources = unpickler.load()
            if not isinstance(sources, list) or not sources or any(_stamp(s[0]) != tuple(s) for s in sources):
                return None
            validator = unpickler.load()
    except Exception:  # missing, truncated, or naming a class the code no longer has
        return None
    return validator if isinstance(validator, SchemaValidator) else None


def _keep(entry: Path, validator: SchemaValidator) -> None:
    """Write the entry (best effort). A validator pydantic wrapped for its plugins is not kept."""
    if type(validator) is not SchemaValidator:
        return
    from ..files import write_best_effort

    buf = io.BytesIO()
    try:
        pickler = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
        pickler.dump(_sources())
        pickler.dump(validator)
    except Exception:  # a validator function pickle cannot name: keep nothing
        return
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    write_best_effort(entry, buf.getvalue())
