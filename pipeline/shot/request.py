"""What `motion render` was asked to do: one `RenderRequest` (the command line as data)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class DeliverView:
    """How the deliverables show the scene-linear frames (--exposure, --ocio, --ocio-display,
    --ocio-view): the arguments of their `telecine.movie.ViewTransform` (None: its default)."""

    exposure: float = 0.0  # stops
    ocio_config: str | None = None  # a config file or ocio://NAME; "none": the plain sRGB curve
    ocio_display: str | None = None
    ocio_view: str | None = None


@dataclass
class RenderRequest:
    """Everything `motion render` was asked to do (flags left None use the defaults)."""

    scene: Path
    output_dir: Path | None = None
    frames_spec: str | None = None  # --frames as typed: '0-119x2'
    frames: tuple[int, ...] | None = None  # frames already chosen by the caller (--fields, cache warm): no text round trip
    preset: str | None = None
    render_overrides: dict[str, Any] = field(default_factory=dict)
    output_overrides: dict[str, Any] = field(default_factory=dict)  # e.g. aovs (--aov)
    cache: bool = True
    deliver: str | None = None
    deliver_frames: str | None = None  # --deliver-frames: deliverables of part of the shot, named apart (default: the whole shot)
    deliver_view: DeliverView = DeliverView()  # exposure / OCIO for the deliverables
    resume: bool = True
    overwrite: bool = False
    shard: str | None = None
    workers: int | None = None
    scheduler: str | None = None
    transfer: str = "auto"  # with --scheduler: ship | shared | auto (docs/farm.md, "A farm without a shared disk")
    threads: int | None = None
    chunk_size: int | None = None
    retries: int | None = None
    task_timeout_s: float | None = None
    motion_file: Path | None = None
    report: Path | None = None
    progress: bool | None = None  # None: a live bar only on a terminal
    check: bool = False  # only verify every selected frame is complete; render nothing
    dry_run: bool = False  # only say what would be done (the plan); write nothing
    fields: str | None = None  # field order (tff/bff): the frames are fields, drawn row by parity (shot/fields.py)
    scene_overrides: dict[str, Any] = field(default_factory=dict)  # further sections merged over the scene (the field timeline)
    compare: Path | None = None  # --compare REF: checked before any frame renders, compared after (shot/compare.py)
