"""Farm stage: frames -> chunks -> workers (local processes or a Dask cluster), with
retries, exclusion of failing workers, timeouts, claims, resume, progress and a report
(docs/farm.md). What a render runs, and in which order, is the shot stage's
(motion.pipeline.shot)."""

from .selection import chunks, default_chunk_size, parse_frames, parse_shard, shard

__all__ = ["chunks", "default_chunk_size", "parse_frames", "parse_shard", "shard"]
