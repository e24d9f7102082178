"""Shot stage: one `motion render` from request to deliverables, above the farm.

`run_render` (render.py) runs the named steps: load the scene with its preset and flags,
select frames (and the shard), size the job, check before any work, bake the motion once
here, skip complete frames, run the chunks on the farm, write the report, then the temporal
pass and the deliverables. `dry_run.py` is `--dry-run` and `--check`, `deliver.py` the
deliverables (checked before the first frame, assembled after the last), `fields.py`
`--fields 60i` (the fields rendered as frames of a field timeline, then woven).

Each name is imported from its module on first use, so that `motion render` loads only
the modules its run takes (a rerun that renders nothing: docs/reruns.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import lazy_names

if TYPE_CHECKING:
    from .dry_run import plan_text
    from .fields import run_field_render
    from .render import run_render
    from .request import DeliverView, RenderRequest

# each public name -> the module of this package that defines it
_HOMES = {"run_field_render": "fields", "plan_text": "dry_run", "run_render": "render", "DeliverView": "request", "RenderRequest": "request"}

__all__ = ["DeliverView", "RenderRequest", "plan_text", "run_field_render", "run_render"]

__getattr__ = lazy_names(__name__, _HOMES)
