"""Load a scene: YAML (safely, with source positions) -> validated, immutable `Scene`.

Every problem becomes one `Problem(file, line, column, yaml_path, message)`; all of them
are collected and raised together as one `SceneError`, before any long job starts.
"""

from __future__ import annotations

import difflib
import os
import stat
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Union

import yaml
from pydantic import BaseModel, ValidationError

from ..errors import InputFileError, Problem, SceneError
from .schema import Scene

Loc = tuple[Union[str, int], ...]

# --- limits on what an input file can make us allocate (docs/scene-format.md, "Limits") ---

MAX_YAML_BYTES = 16 * 1024**2  # a scene or preset file
MAX_DEPTH = 64  # nesting of mappings and sequences
MAX_ALIAS_NODES = 100_000  # nodes aliases may add beyond those written in the file
MAX_INT_CHARS = 32  # characters of one integer literal (int64 needs 19 digits)


def open_bounded(path: str | Path, limit: int, what: str) -> typing.BinaryIO:
    """Open an input file for reading after checking that it is a regular file of at most
    `limit` bytes: a device (/dev/zero), a pipe or a folder is refused before a byte is
    read. The caller closes the file. Raises InputFileError with the reason."""
    file = str(path)
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; fstat then refuses it
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise InputFileError(file, f"{what} not found") from None
    except IsADirectoryError:
        raise InputFileError(file, f"{what} is a folder, not a file") from None
    except OSError as exc:
        raise InputFileError(file, f"cannot read {what}: {exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise InputFileError(file, f"{what} is a folder, not a file")
        if not stat.S_ISREG(st.st_mode):
            raise InputFileError(file, f"{what} is not a regular file (a device, pipe or socket)")
        if st.st_size > limit:
            raise InputFileError(file, f"{what} is {st.st_size} bytes; the limit is {limit} bytes")
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def read_bounded(path: str | Path, limit: int, what: str) -> bytes:
    """The bytes of a regular file of at most `limit` bytes (see `open_bounded`); a file
    that grows past the limit while being read is refused too."""
    with open_bounded(path, limit, what) as fh:
        try:
            # read what fstat promised (+1 to see growth), then more only while under the
            # limit: read(n) reserves n bytes up front, so never ask for the whole limit
            data = fh.read(os.fstat(fh.fileno()).st_size + 1)
            while data and len(data) <= limit:
                more = fh.read(min(1 << 20, limit + 1 - len(data)))
                if not more:
                    break
                data += more
        except OSError as exc:
            raise InputFileError(str(path), f"cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise InputFileError(str(path), f"{what} is over the limit of {limit} bytes")
    return data


def read_yaml_file(path: str | Path, what: str) -> str:
    """A scene or preset file's text, bounded (MAX_YAML_BYTES); SceneError if unreadable."""
    file = str(path)
    try:
        data = read_bounded(path, MAX_YAML_BYTES, what)
        return data.decode("utf-8")
    except InputFileError as exc:
        raise SceneError([Problem(file, None, None, "", exc.reason)]) from None
    except UnicodeDecodeError as exc:
        raise SceneError([Problem(file, None, None, "", f"cannot read {what}: not UTF-8 text ({exc.reason} at byte {exc.start})")]) from None


# --- YAML with positions ------------------------------------------------------------------


class _Loader(yaml.SafeLoader):
    """SafeLoader that also rejects duplicate keys (a silent overwrite hides mistakes),
    bounds nesting depth and integer literals, and records where aliases are used."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self.alias_marks: list[yaml.Mark] = []

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:  # type: ignore[override]
        if self.check_event(yaml.AliasEvent):
            self.alias_marks.append(self.peek_event().start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nesting deeper than {MAX_DEPTH} levels (the limit)", self.peek_event().start_mark
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def _construct_int(loader: _Loader, node: yaml.ScalarNode) -> int:
    if len(str(node.value)) > MAX_INT_CHARS:
        raise yaml.constructor.ConstructorError(
            None, None, f"integer literal of {len(str(node.value))} characters (the limit is {MAX_INT_CHARS})", node.start_mark
        )
    return yaml.SafeLoader.construct_yaml_int(loader, node)


_Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def _expanded_size(root: yaml.Node) -> tuple[int, int, yaml.Node | None]:
    """(nodes written, nodes after expanding every alias, a node that contains itself).

    Iterative, memoised per node: aliases share node objects, so the document is a graph
    whose expansion can be exponential (or, with a recursive anchor, infinite)."""
    size: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            total = 1
            for child in _children(node):
                total += size[id(child)]
            size[key] = total
            continue
        if key in size:
            continue
        if key in on_path:
            return len(size), -1, node
        on_path.add(key)
        stack.append((node, True))
        for child in _children(node):
            if id(child) in on_path:
                return len(size), -1, child
            if id(child) not in size:
                stack.append((child, False))
    return len(size), size[id(root)], None


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _construct_mapping(loader: _Loader, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
    seen: dict[Any, yaml.Node] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(
                None, None, "a mapping key must be a plain scalar", key_node.start_mark
            ) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first at line {seen[key].start_mark.line + 1})", key_node.start_mark
            )
        seen[key] = key_node
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _positions(node: yaml.Node, loc: Loc, out: dict[Loc, tuple[int, int]]) -> None:
    """Record (line, column), 1-based, of every node, keyed by its path from the root."""
    out[loc] = (node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            key = key_node.value
            out[(*loc, key, "__key__")] = (key_node.start_mark.line + 1, key_node.start_mark.column + 1)
            _positions(value_node, (*loc, key), out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _positions(item, (*loc, i), out)


@dataclass(frozen=True)
class SourceMap:
    """Where each value of a YAML document sits in its file."""

    file: str
    positions: dict[Loc, tuple[int, int]]

    def locate(self, loc: Loc, key: bool = False) -> tuple[int | None, int | None]:
        """Position of `loc`, or of its nearest ancestor present in the file."""
        if key and (*loc, "__key__") in self.positions:
            return self.positions[(*loc, "__key__")]
        for n in range(len(loc), -1, -1):
            pos = self.positions.get(tuple(loc[:n]))
            if pos is not None:
                return pos
        return (None, None)

    def sub(self, prefix: Loc) -> "SourceMap":
        """The positions of the part of the document under `prefix`, relative to it."""
        n = len(prefix)
        return SourceMap(self.file, {loc[n:]: pos for loc, pos in self.positions.items() if loc[:n] == prefix})

    def problem(self, loc: Loc, message: str, key: bool = False) -> Problem:
        line, col = self.locate(loc, key=key)
        return Problem(self.file, line, col, yaml_path(loc), message)


def yaml_path(loc: Iterable[str | int]) -> str:
    """('objects', 2, 'motion', 'keys', 1, 'time') -> 'objects[2].motion.keys[1].time'."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def parse_yaml(text: str, file: str) -> tuple[Any, SourceMap]:
    """Parse one YAML document safely; returns the data and its source map."""
    try:
        loader = _Loader(text)
        try:
            node = loader.get_single_node()
            if node is None:
                return None, SourceMap(file, {})
            written, expanded, cyclic = _expanded_size(node)
            if cyclic is not None or expanded - written > MAX_ALIAS_NODES:
                mark = loader.alias_marks[0] if loader.alias_marks else node.start_mark
                why = (
                    "a recursive alias (an anchor used inside itself)"
                    if cyclic is not None
                    else f"aliases expand the document to {expanded} nodes from {written} written (at most {MAX_ALIAS_NODES} more are allowed)"
                )
                raise SceneError([Problem(file, mark.line + 1, mark.column + 1, "", f"invalid YAML: {why}")])
            data = loader.construct_document(node)
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        msg = " ".join(" ".join(str(p).split()) for p in (exc.context, exc.problem) if p)
        if "could not determine a constructor" in msg:
            msg = f"tag not allowed (scene files are plain YAML): {exc.problem}"
        line = mark.line + 1 if mark else None
        col = mark.column + 1 if mark else None
        raise SceneError([Problem(file, line, col, "", f"invalid YAML: {msg}")]) from None
    except yaml.YAMLError as exc:
        raise SceneError([Problem(file, None, None, "", "invalid YAML: " + " ".join(str(exc).split()))]) from None
    positions: dict[Loc, tuple[int, int]] = {}
    _positions(node, (), positions)
    return data, SourceMap(file, positions)


# --- pydantic errors -> problems ----------------------------------------------------------


def _unwrap(tp: Any) -> list[Any]:
    """The concrete alternatives of a (possibly Annotated / Optional / Union) type."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return _unwrap(typing.get_args(tp)[0])
    if origin is Union or str(origin) == "<class 'types.UnionType'>":
        out: list[Any] = []
        for arg in typing.get_args(tp):
            out.extend(_unwrap(arg))
        return out
    return [tp]


def _model_at(root: type[BaseModel], loc: Loc) -> type[BaseModel] | None:
    """The model class that owns the mapping at `loc` (to suggest its field names)."""
    current: list[Any] = [root]
    for part in loc:
        nxt: list[Any] = []
        for tp in current:
            for alt in _unwrap(tp):
                origin = typing.get_origin(alt)
                if isinstance(part, int) and origin in (list, tuple):
                    args = [a for a in typing.get_args(alt) if a is not Ellipsis]
                    if origin is tuple and len(args) > 1:
                        nxt.append(args[part] if part < len(args) else None)
                    elif args:
                        nxt.append(args[0])
                elif isinstance(part, str) and origin is dict:
                    nxt.append(typing.get_args(alt)[1])
                elif isinstance(part, str) and isinstance(alt, type) and issubclass(alt, BaseModel):
                    field = alt.model_fields.get(part)
                    if field is not None:
                        nxt.append(field.annotation)
                    else:
                        # a discriminated-union tag in the location: keep the member it names
                        for f_name in ("type", "shape"):
                            f = alt.model_fields.get(f_name)
                            if f is not None and part in typing.get_args(f.annotation):
                                nxt.append(alt)
        current = [c for c in nxt if c is not None]
        if not current:
            return None
    models = [a for tp in current for a in _unwrap(tp) if isinstance(a, type) and issubclass(a, BaseModel)]
    return models[0] if len(models) == 1 else None




def _strip_tags(loc: Loc, data: Any) -> Loc:
    """Drop pydantic's union-member tags ('sphere', 'float', 'tuple[...]') from a location,
    so that it is the path in the YAML document.

    A string that is not a key of the mapping at that point is a tag, unless it is the
    last part (then it names a missing key)."""
    out: list[str | int] = []
    node = data
    for i, part in enumerate(loc):
        last = i == len(loc) - 1
        if isinstance(part, int) and isinstance(node, (list, tuple)):
            out.append(part)
            node = node[part] if part < len(node) else None
        elif isinstance(node, dict) and part in node:
            out.append(part)
            node = node[part]
        elif isinstance(node, dict) and last:
            out.append(part)
            node = None
        elif node is None and not isinstance(part, int) and last:
            out.append(part)
    return tuple(out)


def _message(err: Mapping[str, Any], data: Any, loc: Loc, root: type[BaseModel]) -> tuple[str, bool]:
    """A human message for one pydantic error; the bool says 'point at the key'."""
    kind = err["type"]
    if kind == "extra_forbidden":
        key = loc[-1] if loc else "?"
        # pydantic's own location keeps the union tags ('sphere'), which name the model
        model = _model_at(root, tuple(err["loc"])[:-1])
        hint = ""
        if model is not None:
            names = list(model.model_fields)
            close = difflib.get_close_matches(str(key), names, n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else f"; expected one of: {', '.join(names)}"
        return f"unknown key '{key}'{hint}", True
    if kind == "missing":
        if loc and isinstance(loc[-1], int):
            return f"too few values: item {loc[-1]} is missing", False
        return "required field is missing", False
    if kind == "union_tag_invalid":
        ctx = err.get("ctx", {})
        tag = ctx.get("tag")
        expected = ctx.get("expected_tags", "")
        options = [t.strip().strip("'") for t in str(expected).split(",")]
        close = difflib.get_close_matches(str(tag), options, n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        return f"unknown {ctx.get('discriminator', 'type').strip(chr(39))} '{tag}'; expected one of: {expected}{hint}", False
    if kind == "union_tag_not_found":
        ctx = err.get("ctx", {})
        return f"missing '{str(ctx.get('discriminator', 'type')).strip(chr(39))}' (it selects the kind)", False
    msg = str(err["msg"])
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    got = err.get("input")
    if kind not in ("model_type", "dict_type") and not isinstance(got, (dict, list)) and got is not None and "got" not in msg:
        shown = repr(got)
        msg += f" (got {shown if len(shown) <= 60 else shown[:57] + '...'})"
    return msg, False


def _is_type_error(err: Mapping[str, Any]) -> bool:
    kind = str(err["type"])
    return kind.endswith("_type") or kind.endswith("_parsing") or kind in ("model_attributes_type", "union_tag_not_found")


def problems_from_validation(exc: ValidationError, data: Any, source: SourceMap, root: type[BaseModel]) -> list[Problem]:
    """One problem per YAML path; the alternatives of a union at one path join in one line."""
    grouped: dict[str, tuple[Loc, bool, list[str]]] = {}
    errors = [(err, _strip_tags(tuple(err["loc"]), data)) for err in exc.errors(include_url=False)]
    specific = [loc for err, loc in errors if not _is_type_error(err)]
    for err, loc in errors:
        # a union branch that merely had the wrong type ('expected a number') is noise when
        # another branch got further and found a real problem at or below this path
        if _is_type_error(err) and any(len(s) > len(loc) and s[: len(loc)] == loc for s in specific):
            continue
        message, at_key = _message(err, data, loc, root)
        path = yaml_path(loc)
        entry = grouped.setdefault(path, (loc, at_key, []))
        if message not in entry[2]:
            entry[2].append(message)
    problems = [source.problem(loc, "; or: ".join(msgs), key=at_key) for loc, at_key, msgs in grouped.values()]
    return sorted(problems, key=lambda p: (p.line or 0, p.column or 0))


# --- entry points -------------------------------------------------------------------------


@dataclass(frozen=True)
class LoadedScene:
    """A validated scene with where it came from (for relative asset paths and errors)."""

    scene: Scene
    path: Path
    source: SourceMap
    data: dict[str, Any]

    @property
    def name(self) -> str:
        return self.scene.name or self.path.stem

    @property
    def base_dir(self) -> Path:
        return self.path.parent

    def asset(self, relative: str) -> Path:
        return (self.base_dir / relative).resolve()


def load_scene(path: str | Path, overrides: Mapping[str, Any] | None = None, assets: bool = True) -> LoadedScene:
    """Read, validate and cross-check a scene file. Raises SceneError with every problem.

    overrides: nested dict merged over the document before validation (presets, CLI flags).
    assets: open and decode every mesh and image the scene names (the validation stage);
    a worker reloading a scene the main process has already checked passes False.
    """
    path = Path(path)
    file = str(path)
    text = read_yaml_file(path, "scene file")
    data, source = parse_yaml(text, file)
    if data is None:
        raise SceneError([Problem(file, 1, 1, "", "the scene file is empty; expected a mapping with at least 'camera'")])
    if not isinstance(data, dict):
        raise SceneError([source.problem((), f"expected a mapping at the top level, got {type(data).__name__}")])
    if overrides:
        data = deep_merge(data, overrides)
    from .imports import expand_imports

    data, source = expand_imports(data, source, path.parent)
    try:
        scene = Scene.model_validate(data)
    except ValidationError as exc:
        raise SceneError(problems_from_validation(exc, data, source, Scene)) from None
    from .checks import semantic_problems

    problems = semantic_problems(scene, path.parent, source, assets=assets)
    if problems:
        raise SceneError(problems)
    return LoadedScene(scene=scene, path=path.resolve(), source=source, data=data)


def deep_merge(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """Merge `over` into a copy of `base`; nested mappings merge, everything else replaces."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out
