"""The names of a frame's and a chunk's states, and which of them are final: what the
report totals (farm/report.py) and the state machine moves between (farm/lifecycle.py),
apart from the machine, whose classes a run that renders nothing never loads."""

from __future__ import annotations

from typing import Literal, get_args

FrameState = Literal["queued", "running", "held", "stopped", "rendered", "skipped", "done_elsewhere", "failed", "not_rendered"]
FRAME_STATES: tuple[FrameState, ...] = get_args(FrameState)
FINAL_FRAME_STATES: tuple[FrameState, ...] = ("rendered", "skipped", "done_elsewhere", "failed", "not_rendered")  # the report totals each

ChunkState = Literal["queued", "running", "done", "lost", "stopped", "failed"]
CHUNK_STATES: tuple[ChunkState, ...] = get_args(ChunkState)
FINAL_CHUNK_STATES: tuple[ChunkState, ...] = ("done", "lost", "stopped", "failed")
