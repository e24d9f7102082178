"""Farm stage: frames -> chunks -> workers (local processes or a Dask cluster), with
retries, exclusion of failing workers, timeouts, claims, resume, progress and a report
(docs/farm.md)."""

from .frames import chunks, default_chunk_size, parse_frames, parse_shard, shard
from .run import RenderRequest, run_render

__all__ = ["RenderRequest", "chunks", "default_chunk_size", "parse_frames", "parse_shard", "run_render", "shard"]
