"""Pydantic validation errors -> located problems: one `Problem` per YAML path, with the
union alternatives at one path joined, pydantic's union tags dropped from the location, and
a suggestion for a misspelt key or kind."""

from __future__ import annotations

import typing
from typing import Any, Mapping, Union

from pydantic import BaseModel, ValidationError

from ..errors import Problem
from .source import Loc, SourceMap, yaml_path


def closest(word: object, options: list[str], cutoff: float = 0.6) -> str | None:
    """The option a misspelt key, kind, choice or name most likely meant, or None: compared
    without case (`CCD` -> `ccd`, `HALF` -> `half`), as difflib rates them.

    >>> closest("catmul-rom", ["linear", "catmull-rom"]), closest("CCD", ["two-bone", "ccd"])
    ('catmull-rom', 'ccd')
    """
    lowered: dict[str, str] = {}
    for option in options:
        lowered.setdefault(option.lower(), option)
    import difflib  # only a misspelt name needs it

    found = difflib.get_close_matches(str(word).lower(), list(lowered), n=1, cutoff=cutoff)
    return lowered[found[0]] if found else None


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
            close = closest(key, names)
            hint = f"; did you mean '{close}'?" if close else f"; expected one of: {', '.join(names)}"
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
        close = closest(tag, options, cutoff=0.5)
        hint = f"; did you mean '{close}'?" if close else ""
        return f"unknown {ctx.get('discriminator', 'type').strip(chr(39))} '{tag}'; expected one of: {expected}{hint}", False
    if kind == "union_tag_not_found":
        ctx = err.get("ctx", {})
        return f"missing '{str(ctx.get('discriminator', 'type')).strip(chr(39))}' (it selects the kind)", False
    if kind == "literal_error":
        # a misspelt choice gets the same help as a misspelt key
        options = [o.strip().strip("'") for o in str(err.get("ctx", {}).get("expected", "")).replace(" or ", ", ").split(",")]
        close = closest(err.get("input"), [o for o in options if o])
        if close:
            return f"{err['msg']} (got {err.get('input')!r}); did you mean '{close}'?", False
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

