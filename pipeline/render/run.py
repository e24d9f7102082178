"""Moved: orchestration of `motion render` is the farm stage's (motion.pipeline.farm.run).
Re-exported here so existing imports keep working."""

from ..farm.frames import parse_frames
from ..farm.run import RenderRequest, run_render

__all__ = ["RenderRequest", "parse_frames", "run_render"]
