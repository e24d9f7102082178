"""Source positions: a YAML document parsed safely with the line and column of every value.

`parse_yaml` returns the data and its `SourceMap`; `SourceMap.problem(loc, message)` makes a
`Problem` located at `loc` (or its nearest ancestor written in the file); `yaml_path` spells a
location as a user reads it. Scene and preset loading, the semantic checks and the imports
all locate their problems through this module.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable, Union

import yaml

from ..errors import InputFileError, Problem, SceneError
from ..limits import read_bounded

Loc = tuple[Union[str, int], ...]

# --- limits on what an input file can make us allocate (docs/scene-format.md, "Limits") ---

MAX_YAML_BYTES = 16 * 1024**2  # a scene or preset file
MAX_DEPTH = 64  # nesting of mappings and sequences
MAX_YAML_NODES = 200_000  # values written in one file (PyYAML composes ~50k a second)
MAX_ALIAS_NODES = 100_000  # nodes aliases may add beyond those written in the file
MAX_INT_CHARS = 32  # characters of one integer literal (int64 needs 19 digits)
TOO_MANY_NODES = f"more than {MAX_YAML_NODES} values in one file (the limit; long data such as keys belongs in an import or a bake file)"
TOO_DEEP = f"nesting deeper than {MAX_DEPTH} levels (the limit)"


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
        self._nodes = getattr(self, "_nodes", 0) + 1
        try:
            if self._nodes > MAX_YAML_NODES:
                raise _limit(TOO_MANY_NODES, self.peek_event().start_mark)
            if self._depth > MAX_DEPTH:
                raise _limit(TOO_DEEP, self.peek_event().start_mark)
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


_SURROGATE = re.compile("[\ud800-\udfff]")


def _surrogate_problems(data: Any, smap: "SourceMap") -> list[Problem]:
    """Each string (value or key) holding a lone surrogate, located: "\\ud800" escaped in a
    double-quoted string is no character, and no UTF-8 file name, EXR header or report can
    hold it (the validator took it and every frame failed on writing it)."""
    problems: list[Problem] = []
    stack: list[tuple[Any, Loc]] = [(data, ())]
    while stack:
        value, loc = stack.pop()
        items: Iterable[tuple[Any, Any]] = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, (list, tuple, set, frozenset)) else ()
        if isinstance(value, str):
            found = _SURROGATE.search(value)
            if found:
                problems.append(smap.problem(loc, f"a lone surrogate \\u{ord(found.group()):04x} in a string is not a character (write the character itself, or its \\U escape)"))
            continue
        for key, item in items:
            if isinstance(key, str) and _SURROGATE.search(key):
                problems.append(smap.problem((*loc, key), f"a lone surrogate \\u{ord(_SURROGATE.search(key).group()):04x} in a key is not a character", key=True))  # type: ignore[union-attr]
            stack.append((item, (*loc, key)))
    # a path through a bad key is printed with the key escaped (stderr cannot encode it)
    escaped = [replace(p, yaml_path=p.yaml_path.encode("utf-8", "backslashreplace").decode("ascii", "replace")) for p in problems]
    return sorted(escaped, key=lambda p: (p.line or 0, p.column or 0))


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
        """A Problem located at `loc` (its key when `key`), or at its nearest ancestor in the file."""
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


class _CLoader(yaml.CSafeLoader):  # type: ignore[misc]
    """libyaml (C) parses and composes; the constructors are _Loader's."""

    yaml_constructors = _Loader.yaml_constructors


class _Reparse(Exception):
    """The fast path met something only the Python parser words as we want: parse again there."""


def _compose(text: str) -> tuple[yaml.Node | None, _Loader, list[yaml.Mark]]:
    """The document's node graph by PyYAML's own parser (the reference for every error message)."""
    loader = _Loader(text)
    try:
        return loader.get_single_node(), loader, loader.alias_marks
    except BaseException:
        loader.dispose()
        raise


# What the two readers read differently (found by tests/scene/test_yaml_readers.py's fuzz), so
# the fast path leaves it to PyYAML, whose meaning is the reference: a tab (libyaml takes it
# as white space after a key, in a flow, before a comment: PyYAML refuses it); a BOM after
# the first character (libyaml drops a second one at the start, and one alone on a line);
# `?` (PyYAML ends a plain scalar in a flow there, libyaml does not); `!`, a tag (the
# non-specific `!` alone is an empty string to libyaml and null to PyYAML; a tag in a flow
# ends at `,` for libyaml only); NEL and the Unicode line and paragraph separators (line
# breaks to PyYAML only); a comment right after a block scalar's indicator (`|#`: libyaml
# takes it). A BOM as the first character is the encoding's: the search starts after it.
_READERS_DIFFER = re.compile("[\t?!\ufeff\x85\u2028\u2029]|[|>][-+0-9]*#")


def _compose_fast(text: str) -> tuple[yaml.Node | None, _CLoader, list[yaml.Mark]]:
    """The same node graph by libyaml, about ten times faster (docs/ci-sharding.md, "What
    validation keeps"): one pass over its events bounds nesting and values written first,
    as `_Loader.compose_node` does (libyaml composes recursively, in C), with the same errors.
    A character PyYAML refuses, or any error of libyaml's, raises _Reparse: `_compose`
    then refuses the document in PyYAML's words."""
    if yaml.reader.Reader.NON_PRINTABLE.search(text) or _READERS_DIFFER.search(text, 1 if text[:1] == "\ufeff" else 0):
        raise _Reparse
    alias_marks: list[yaml.Mark] = []
    try:
        depth = nodes = 0
        for event in yaml.parse(text, Loader=yaml.CSafeLoader):
            if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
                continue
            if not isinstance(event, yaml.NodeEvent):
                continue
            if isinstance(event, yaml.AliasEvent):
                alias_marks.append(event.start_mark)
            elif event.tag is not None or (isinstance(event, yaml.ScalarEvent) and not event.style and event.value == ""):
                raise _Reparse  # a tag, or an empty plain value (libyaml places it at the next token, PyYAML where it ends)
            nodes += 1
            if nodes > MAX_YAML_NODES:
                raise _limit(TOO_MANY_NODES, event.start_mark)
            if depth + 1 > MAX_DEPTH:
                raise _limit(TOO_DEEP, event.start_mark)
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
        loader = _CLoader(text)
        try:
            return loader.get_single_node(), loader, alias_marks
        except BaseException:
            loader.dispose()
            raise
    except _Limit:
        raise
    except yaml.YAMLError:
        raise _Reparse from None


class _Limit(yaml.composer.ComposerError):
    """A bound of this module's, met while composing."""


def _limit(message: str, mark: yaml.Mark) -> _Limit:
    return _Limit(None, None, message, mark)


def parse_yaml(text: str, file: str) -> tuple[Any, SourceMap]:
    """Parse one YAML document safely; returns the data and its source map."""
    try:
        try:
            node, loader, alias_marks = _compose_fast(text)
        except _Reparse:
            node, loader, alias_marks = _compose(text)
        try:
            if node is None:
                return None, SourceMap(file, {})
            written, expanded, cyclic = _expanded_size(node)
            if cyclic is not None or expanded - written > MAX_ALIAS_NODES:
                mark = alias_marks[0] if alias_marks else node.start_mark
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
    smap = SourceMap(file, positions)
    if "\\u" in text or "\\U" in text:  # a surrogate can only be written as an escape
        problems = _surrogate_problems(data, smap)
        if problems:
            raise SceneError(problems)
    return data, smap


# --- a parse kept between processes ------------------------------------------------------

MAX_KEPT_BYTES = 64 << 20  # a kept document's JSON (aliases can make it larger than its file)


class DeferredSourceMap(SourceMap):
    """The source map of a document read back from the cache layer (`parse_kept`): its
    positions are parsed from the text only when something asks where a value is (a
    problem to locate), never on a scene without problems."""

    def __init__(self, file: str, text: str) -> None:
        object.__setattr__(self, "file", file)
        object.__setattr__(self, "_text", text)

    def __getattr__(self, name: str) -> Any:
        if name != "positions":
            raise AttributeError(name)
        positions = parse_yaml(self._text, self.file)[1].positions  # type: ignore[attr-defined]
        object.__setattr__(self, "positions", positions)
        return positions

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SourceMap) and (self.file, self.positions) == (other.file, other.positions)

    __hash__ = None  # type: ignore[assignment]


def parse_kept(text: str, file: str) -> tuple[Any, SourceMap]:
    """`parse_yaml` through the cache layer (`cache.STORES["parsed"]`): a document this
    parser read before (the same bytes) comes back from its JSON, with its source map
    deferred (`DeferredSourceMap`); else it is parsed now and kept when its JSON gives it
    back equal (plain mappings with text keys, lists, text, numbers, booleans, nulls: a
    scene always is). Parsing with positions is most of loading a large scene (a
    2,000-object file: 0.7 s, against 0.03 s read back), which `motion render` pays in
    the main process and again in every worker. A document that fails to parse is never
    kept, so its problems are found and located as before."""
    import hashlib
    import json

    from ..cache import STORES

    store = STORES["parsed"]
    entry = store.path(store.key(hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()), suffix=".json")
    if store.hit(entry):
        raw = store.read(entry, MAX_KEPT_BYTES)
        try:
            data = json.loads(raw) if raw is not None else None
        except ValueError:
            data = None
        if isinstance(data, dict):
            return data, DeferredSourceMap(file, text)
    data, source = parse_yaml(text, file)
    if isinstance(data, dict):
        try:
            kept = json.dumps(data, separators=(",", ":"), allow_nan=False)
        except (TypeError, ValueError, RecursionError):  # a value JSON cannot hold (a date, a NaN): not kept
            kept = None
        if kept is not None and len(kept) <= MAX_KEPT_BYTES and json.loads(kept) == data:
            store.put(entry, kept.encode(), best_effort=True, doing="keeping a parsed scene file")
    return data, source
