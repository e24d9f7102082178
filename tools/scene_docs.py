"""Generate the field reference of docs/scene-format.md from the scene schema.

    python tools/scene_docs.py          # rewrite the generated part of the doc
    python tools/scene_docs.py --check  # exit 1 if the doc is out of date (a test runs this)

Everything between the BEGIN/END markers is generated: one table per record with each
field's type, default, allowed range, unit and meaning (the unit and meaning from the field's
pydantic metadata where the schema declares them). The prose around it is hand-written.
"""

from __future__ import annotations

import sys
import typing
from pathlib import Path
from typing import Any

from annotated_types import MaxLen, MinLen
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

DOC = Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"
BEGIN = "<!-- BEGIN GENERATED FIELD REFERENCE (tools/scene_docs.py) -->"
END = "<!-- END GENERATED FIELD REFERENCE -->"

# A field's unit is declared at the schema (`Field(json_schema_extra={"unit": ...})`, with its
# `description` beside it) where its name alone does not say it (`start` is a time in one record
# and a position in another; `rate` is particles or degrees per second). Otherwise it comes
# from this table by the field's name (SI; angles in degrees), and only for a field that holds
# numbers: a name, a choice, a flag or a record has no unit.
UNITS = {
    "fps": "frames/s", "fov": "degrees", "angle": "degrees", "cutoff_angle": "degrees", "beam_width": "degrees",
    "ortho_width": "m", "near": "m", "far": "m", "position": "m", "look_at": "m", "translate": "m",
    "radius": "m", "size": "m", "width": "m", "height": "m", "mass": "kg", "velocity": "m/s",
    "angular_velocity": "degrees/s", "step": "s", "gravity": "m/s^2", "air_density": "kg/m^3",
    "density": "kg/m^3", "level": "m", "stiffness": "N/m", "damping": "N s/m", "rest_length": "m",
    "lifetime": "s", "speed": "m/s", "speed_spread": "m/s",
    "spread": "degrees", "x0": "m", "v0": "m/s", "a": "m/s^2", "t0": "s",
    "period": "s", "phase": "degrees", "frequency": "Hz", "radiance": "W sr^-1 m^-2", "intensity": "W sr^-1",
    "irradiance": "W m^-2", "area": "m^2", "linear": "N s/m", "softening": "m", "G": "N m^2 kg^-2",
    "euler": "degrees", "time": "frames or s (time_unit)", "translate_amplitude": "m", "rotate_amplitude": "degrees",
}


def _leaves(tp: Any) -> list[Any]:
    """The plain types a field's type is made of (through Annotated, unions, tuples, lists)."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return _leaves(typing.get_args(tp)[0])
    if origin is typing.Literal:
        return [typing.Literal]
    if origin is not None:
        return [leaf for a in typing.get_args(tp) if a is not Ellipsis for leaf in _leaves(a)]
    return [tp]


def _unit(name: str, field: Any) -> str:
    """The field's unit: declared at the schema, else by its name for a field of numbers."""
    extra = field.json_schema_extra if isinstance(field.json_schema_extra, dict) else {}
    if "unit" in extra:
        return str(extra["unit"])
    numeric = any(isinstance(t, type) and issubclass(t, (int, float)) and t is not bool for t in _leaves(field.annotation))
    return UNITS.get(name, "") if numeric else ""


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{a}`" for a in args)
    if origin in (typing.Union,) or str(origin) == "<class 'types.UnionType'>":
        parts = [_type_name(a) for a in args if a is not type(None)]
        return " or ".join(dict.fromkeys(parts))
    if origin is tuple:
        inner = [_type_name(a) for a in args if a is not Ellipsis]
        if len(set(inner)) == 1:
            return f"[{inner[0]} x{len(inner)}]"
        return "[" + ", ".join(inner) + "]"
    if origin is list:
        return f"list of {_type_name(args[0])}"
    if origin is dict:
        return f"map of {_type_name(args[1])}"
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return f"[{tp.__name__}](#{tp.__name__.lower()})"
    return getattr(tp, "__name__", str(tp)).replace("NoneType", "null")


def _range(field: Any) -> str:
    bits = []
    lengths: list[int | None] = [None, None]  # MinLen, MaxLen
    metas = list(field.metadata)
    tp = field.annotation
    while typing.get_origin(tp) is typing.Annotated:
        metas += list(typing.get_args(tp)[1:])
        tp = typing.get_args(tp)[0]
    for m in metas:
        for attr, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            v = getattr(m, attr, None)
            if v is not None:
                bits.append(f"{sym} {v}")
        if isinstance(m, MinLen):
            lengths[0] = m.min_length
        if isinstance(m, MaxLen):
            lengths[1] = m.max_length
    things = "characters" if tp is str else "items"
    if lengths[0] is not None and lengths[1] is not None:
        bits.append(f"{lengths[0]} to {lengths[1]} {things}")
    elif lengths[0] is not None:
        bits.append(f"at least {lengths[0]} {things[:-1] if lengths[0] == 1 else things}")
    elif lengths[1] is not None:
        bits.append(f"at most {lengths[1]} {things}")
    return ", ".join(dict.fromkeys(bits))


def _default(field: Any) -> str:
    if field.is_required():
        return "**required**"
    d = field.default
    if d is PydanticUndefined:
        return "-"
    if isinstance(d, BaseModel):
        return f"{type(d).__name__} defaults"
    if d is None:
        return "null"
    return f"`{d}`"


def _models(root: type[BaseModel]) -> list[type[BaseModel]]:
    seen: list[type[BaseModel]] = []

    def visit(tp: Any) -> None:
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            if tp in seen:
                return
            seen.append(tp)
            for f in tp.model_fields.values():
                visit(f.annotation)
            return
        for a in typing.get_args(tp):
            visit(a)

    visit(root)
    return seen


def generate() -> str:
    from motion.pipeline.scene.schema import Scene

    out = [BEGIN, ""]
    for model in _models(Scene):
        out.append(f"### {model.__name__}")
        doc = (model.__doc__ or "").strip()
        if doc and not doc.startswith(("Usage docs", "!!! abstract")):
            out.append("")
            out.append(" ".join(doc.split()))
        out += ["", "| field | type | default | range | unit | meaning |", "|---|---|---|---|---|---|"]
        for name, field in model.model_fields.items():
            meaning = " ".join((field.description or "").split())
            out.append(f"| `{name}` | {_type_name(field.annotation)} | {_default(field)} | {_range(field)} | {_unit(name, field)} | {meaning} |")
        out.append("")
    out.append(END)
    return "\n".join(out)


def main(argv: list[str]) -> int:
    text = DOC.read_text()
    head, _, rest = text.partition(BEGIN)
    _, _, tail = rest.partition(END)
    new = head + generate() + tail
    if "--check" in argv:
        if new != text:
            print(f"{DOC} is out of date: run python tools/scene_docs.py", file=sys.stderr)
            return 1
        return 0
    DOC.write_text(new)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
