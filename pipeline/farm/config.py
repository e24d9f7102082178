"""Farm settings: `configs/farm.yaml` (shipped as `motion.configs`), overridden by flags."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import yaml

from ..errors import UsageError


@dataclass(frozen=True)
class FarmConfig:
    """retries: extra attempts per chunk after its first failure; task_timeout_s: a chunk
    running longer is cancelled (its worker stopped) and retried; chunk_size: frames per
    task, None for automatic; max_worker_failures: failures after which a worker is
    excluded for the job; claim_stale_s: age after which another render's claim on a frame
    is considered abandoned (default: the task timeout)."""

    retries: int = 2
    task_timeout_s: float = 1800.0
    chunk_size: int | None = None
    max_worker_failures: int = 3
    claim_stale_s: float | None = None

    @property
    def stale_after_s(self) -> float:
        """Seconds after which another job's claim counts as abandoned (claim_stale_s, else the task timeout)."""
        return self.claim_stale_s if self.claim_stale_s is not None else self.task_timeout_s

    def with_overrides(self, **flags: Any) -> "FarmConfig":
        """A copy with every non-None flag applied (CLI flags beat farm.yaml)."""
        return replace(self, **{k: v for k, v in flags.items() if v is not None})


def load_farm_config() -> FarmConfig:
    """Read configs/farm.yaml; unknown keys or bad values are a UsageError."""
    from ..presets import configs_dir

    text = (configs_dir() / "farm.yaml").read_text()
    data = yaml.safe_load(text) or {}
    known = {"retries", "task_timeout_s", "chunk_size", "max_worker_failures", "claim_stale_s"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise UsageError(f"configs/farm.yaml: unknown keys {unknown}; known: {sorted(known)}")
    chunk = data.get("chunk_size", None)
    if chunk in ("auto", None):
        chunk = None
    try:
        cfg = FarmConfig(
            retries=int(data.get("retries", 2)),
            task_timeout_s=float(data.get("task_timeout_s", 1800)),
            chunk_size=int(chunk) if chunk is not None else None,
            max_worker_failures=int(data.get("max_worker_failures", 3)),
            claim_stale_s=float(data["claim_stale_s"]) if data.get("claim_stale_s") is not None else None,
        )
    except (TypeError, ValueError) as exc:
        raise UsageError(f"configs/farm.yaml: {exc}") from None
    if cfg.retries < 0 or cfg.task_timeout_s <= 0 or cfg.max_worker_failures < 1 or (cfg.chunk_size is not None and cfg.chunk_size < 1):
        raise UsageError(f"configs/farm.yaml: out-of-range value in {cfg}")
    return cfg
