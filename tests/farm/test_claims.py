"""Frame claims (farm/claims.py): when a claim is stale, whatever its date or the limit."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest


def test_a_claim_dated_in_the_future_is_stale(tmp_path: Path) -> None:
    """A claim whose file says it was made a day from now would never age: the job would
    wait on it forever. Past any clock skew (5 min) it protects nothing."""
    import socket
    import time

    from motion.pipeline.farm.claims import MAX_CLOCK_SKEW_S, claim_path, is_stale

    claim = claim_path(tmp_path / "f.0000.exr")
    claim.parent.mkdir()
    info = {"run_id": "other", "pid": 1, "host": "another-" + socket.gethostname()}
    claim.write_text(json.dumps(info))
    os.utime(claim, (time.time() + 86400, time.time() + 86400))
    assert is_stale(claim, info, stale_after_s=1800)
    os.utime(claim, (time.time() + MAX_CLOCK_SKEW_S / 2,) * 2)  # a little skew is trusted
    assert not is_stale(claim, info, stale_after_s=1800)


@pytest.mark.parametrize("limit", [float("nan"), float("inf"), 1e12])
def test_claim_staleness_is_bounded_whatever_the_limit(tmp_path: Path, limit: float) -> None:
    """A NaN or infinite stale limit (`--task-timeout nan` was accepted) made `age > limit`
    false for ever: a dead host's claim held its frame for good. Staleness is bounded
    (claims.MAX_STALE_AFTER_S), and the option refuses such values in one line."""
    import socket
    import time

    from motion.pipeline.farm.claims import MAX_STALE_AFTER_S, claim_path, is_stale

    claim = claim_path(tmp_path / "f.0000.exr")
    claim.parent.mkdir()
    info = {"run_id": "other", "pid": 1, "host": "another-" + socket.gethostname()}
    claim.write_text(json.dumps(info))
    old = time.time() - MAX_STALE_AFTER_S - 60
    os.utime(claim, (old, old))
    assert is_stale(claim, info, stale_after_s=limit)
    os.utime(claim, None)  # a fresh claim of a live job still protects its frame
    assert not is_stale(claim, info, stale_after_s=limit)
