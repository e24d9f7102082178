"""Frame grammar, shards, chunks, farm config and claims (no rendering)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motion.pipeline.errors import UsageError
from motion.pipeline.farm.claims import Claimant, claim_path, release, try_claim
from motion.pipeline.farm.config import FarmConfig, load_farm_config
from motion.pipeline.farm.selection import chunks, default_chunk_size, format_frames, parse_frames, parse_shard, shard


@pytest.mark.parametrize(
    "spec, expected",
    [
        ("0-4", [0, 1, 2, 3, 4]),
        ("0-9x2", [0, 2, 4, 6, 8]),
        ("0-9x3", [0, 3, 6, 9]),
        ("1,5,9", [1, 5, 9]),
        ("7", [7]),
        ("1,3-5,10-20x5, 4", [1, 3, 4, 5, 10, 15, 20]),
        ("-3--1,0", [-3, -2, -1, 0]),
        ("5,5,5", [5]),
    ],
)
def test_frame_grammar(spec: str, expected: list[int]) -> None:
    assert parse_frames(spec) == expected


@pytest.mark.parametrize(
    "spec, needle",
    [("", "empty"), ("5-2", "reversed"), ("0-9x0", "at least 1"), ("a-b", "cannot read"), ("1,,2", "cannot read"), ("0-10x", "cannot read"), ("1.5", "cannot read")],
)
def test_frame_grammar_errors(spec: str, needle: str) -> None:
    with pytest.raises(UsageError, match=needle):
        parse_frames(spec)


def test_frames_outside_timeline() -> None:
    with pytest.raises(UsageError, match="outside the scene's timeline 0-47"):
        parse_frames("40-50", 0, 47)


@pytest.mark.parametrize("spec", ["0/3", "4/3", "1/0", "x", "1-3", ""])
def test_shard_spec_errors(spec: str) -> None:
    with pytest.raises(UsageError, match="--shard"):
        parse_shard(spec)


@settings(max_examples=300, deadline=None)
@given(lo=st.integers(-50, 200), length=st.integers(0, 400), step=st.integers(1, 7), n=st.integers(1, 8))
def test_shards_cover_every_frame_exactly_once(lo: int, length: int, step: int, n: int) -> None:
    spec = f"{lo}-{lo + length}x{step}"
    frames = parse_frames(spec)
    assert frames == list(range(lo, lo + length + 1, step))
    parts = [shard(frames, i, n) for i in range(1, n + 1)]
    flat = [f for p in parts for f in p]
    assert flat == frames  # every frame once, in order, parts contiguous
    sizes = [len(p) for p in parts]
    assert max(sizes) - min(sizes) <= 1  # balanced
    assert parts == [shard(frames, i, n) for i in range(1, n + 1)]  # deterministic
    # format_frames round-trips through the grammar
    if frames:
        assert parse_frames(format_frames(frames)) == frames


@settings(max_examples=200, deadline=None)
@given(frames=st.lists(st.integers(-100, 1000), unique=True, max_size=200).map(sorted), size=st.integers(1, 12))
def test_chunks_partition(frames: list[int], size: int) -> None:
    cs = chunks(frames, size)
    assert [f for c in cs for f in c] == frames
    assert all(1 <= len(c) <= size for c in cs)
    assert all(len(c) == size for c in cs[:-1])


def test_default_chunk_size() -> None:
    assert default_chunk_size(24, 2) == 3
    assert default_chunk_size(1, 8) == 1
    assert default_chunk_size(10_000, 2) == 8
    assert default_chunk_size(0, 2) == 1


def test_farm_config_defaults_and_overrides() -> None:
    cfg = load_farm_config()
    assert cfg == FarmConfig(retries=2, task_timeout_s=1800.0, chunk_size=None, max_worker_failures=3)
    assert cfg.with_overrides(retries=0, chunk_size=None).retries == 0
    assert cfg.stale_after_s == 1800.0


def test_claims_are_exclusive(tmp_path) -> None:
    frame = tmp_path / "a.0001.exr"
    me, other = Claimant.here("run-a"), Claimant.here("run-b")
    assert try_claim(frame, me, 60) == (True, None)
    ok, holder = try_claim(frame, other, 60)
    assert not ok and holder["run_id"] == "run-a"
    assert try_claim(frame, me, 60)[0]  # our own run takes over (a retry after a death)
    release(frame, "run-b")  # not theirs to release
    assert claim_path(frame).exists()
    release(frame, "run-a")
    assert not claim_path(frame).exists()
    assert try_claim(frame, other, 60)[0]


def test_stale_claims_are_broken(tmp_path) -> None:
    frame = tmp_path / "a.0002.exr"
    # a claim held by a process that no longer exists (on this host)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True).stdout.strip()
    ghost = Claimant(run_id="run-ghost", host=Claimant.here("x").host, pid=int(dead))
    assert try_claim(frame, ghost, 60)[0]
    assert try_claim(frame, Claimant.here("run-new"), 60)[0]
    assert json.loads(claim_path(frame).read_text())["run_id"] == "run-new"
    # a claim older than the staleness limit, held by a live process elsewhere
    frame2 = tmp_path / "a.0003.exr"
    remote = Claimant(run_id="run-remote", host="elsewhere", pid=1)
    assert try_claim(frame2, remote, 60)[0]
    assert not try_claim(frame2, Claimant.here("run-new"), 60)[0]
    old = claim_path(frame2).stat().st_mtime - 120
    os.utime(claim_path(frame2), (old, old))
    assert try_claim(frame2, Claimant.here("run-new"), 60)[0]
