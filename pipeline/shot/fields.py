"""`motion render --fields 60i`: the video's fields rendered directly, each a frame of a
field timeline (its own instant and shutter, only its rows), through the same render as
frames, then woven into interlaced EXRs and a movie (telecine/interlace.py)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from ..errors import UsageError
from ..farm.selection import parse_frames
from ..presets import load_preset, overrides_from, spread
from ..scene.loader import load_scene
from ..field_model import check_field_order
from .render import run_render
from .request import RenderRequest


def run_field_render(req: RenderRequest, fields: str, order: str) -> dict[str, Any]:
    """`motion render --fields 60i`: render the fields of the scene's time span (or of the
    interlaced frames `req.frames_spec` names, or the preset's spread of them) into
    OUT/fields/ through the farm, then weave them into OUT (EXRs and a movie)."""
    from ..telecine.interlace import field_range, field_rate, weave_fields

    rate = field_rate(fields)
    fo = check_field_order(order)
    for flag, value in (("--deliver", req.deliver), ("--shard", req.shard), ("--motion", req.motion_file)):
        if value:
            raise UsageError(f"--fields renders and weaves its own fields; it does not combine with {flag}")
    preset = load_preset(req.preset)[0] if req.preset else None
    loaded = load_scene(req.scene, overrides_from(preset, {"render": req.render_overrides}))
    scene = loaded.scene
    if scene.render.resolution[1] % 2:
        raise UsageError(f"--fields: the height {scene.render.resolution[1]} is odd; interlaced frames need an even number of rows")
    tl = scene.timeline
    f0, f1 = field_range(tl.rate, tl.first, tl.last, rate)
    video = list(range(f0 // 2, f1 // 2 + 1))
    if req.frames_spec:
        chosen = parse_frames(req.frames_spec, video[0], video[-1])
    else:
        chosen = spread(video, preset.frame_count if preset else None)
    selected = [f for k in chosen for f in (2 * k, 2 * k + 1)]
    out_dir = Path(req.output_dir or scene.output.directory or Path("out") / loaded.name).resolve()
    sub = dataclasses.replace(
        req,
        output_dir=out_dir / "fields",
        frames_spec=None,
        frames=tuple(selected),
        fields=fo,
        scene_overrides={"timeline": {"fps": str(rate), "first": f0, "last": f1}},
    )
    report = run_render(sub)
    if not req.check:
        weave_fields(out_dir / "fields", out_dir, loaded.name, fo, rate, pixel_type=scene.output.pixel_type, compression=scene.output.compression)
    return report
