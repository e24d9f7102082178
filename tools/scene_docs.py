"""Generate the field reference of docs/scene-format.md from the scene schema.

    python tools/scene_docs.py          # rewrite the generated part of the doc
    python tools/scene_docs.py --check  # exit 1 if the doc is out of date (a test runs this)

Everything between the BEGIN/END markers is generated: one table per record with each
field's type, default, allowed range and unit. The prose around it is hand-written.
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

# Units by field name (SI; angles in degrees). Fields not listed are unitless.
UNITS = {
    "fps": "frames/s", "fov": "degrees", "angle": "degrees", "cutoff_angle": "degrees", "beam_width": "degrees",
    "ortho_width": "m", "near": "m", "far": "m", "position": "m", "look_at": "m", "translate": "m",
    "radius": "m", "size": "m", "width": "m", "height": "m", "mass": "kg", "velocity": "m/s",
    "angular_velocity": "degrees/s", "step": "s", "gravity": "m/s^2", "air_density": "kg/m^3",
    "density": "kg/m^3", "level": "m", "stiffness": "N/m", "damping": "N s/m", "rest_length": "m",
    "rate": "1/s (emitter) or degrees/s (turntable)", "lifetime": "s", "speed": "m/s", "speed_spread": "m/s",
    "spread": "degrees", "start": "s", "stop": "s", "x0": "m", "v0": "m/s", "a": "m/s^2", "t0": "s",
    "period": "s", "phase": "degrees", "frequency": "Hz", "radiance": "W sr^-1 m^-2", "intensity": "W sr^-1",
    "irradiance": "W m^-2", "area": "m^2", "linear": "N s/m", "softening": "m", "G": "N m^2 kg^-2",
    "euler": "degrees", "time": "frames or s (time_unit)", "translate_amplitude": "m", "rotate_amplitude": "degrees",
}


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
            bits.append(f"at least {m.min_length} items")
        if isinstance(m, MaxLen):
            bits.append(f"at most {m.max_length}")
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
        out += ["", "| field | type | default | range | unit |", "|---|---|---|---|---|"]
        for name, field in model.model_fields.items():
            out.append(f"| `{name}` | {_type_name(field.annotation)} | {_default(field)} | {_range(field)} | {UNITS.get(name, '')} |")
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
