"""`motion compare NEW REF`: two EXR sequences, frame by frame (docs/compare.md).

Frames pair by number. Each pair is read (frames.read_pixels), checked for being made
alike (frames.differences against the golden manifest, or the reference frame's own header
when REF is a plain folder), then tested (stats.compare_frame) on the noisy beauty when both
frames keep one (a denoiser's output has no per-pixel noise left to measure), else on the
beauty. A frame that differs gets a perceptual score: NVIDIA's FLIP (`flip-evaluator`,
HDR-FLIP on the linear beauty), its mean and the FLIP map for the report.

Frames are tested in a pool of processes (two on two cores) when there are many.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import FrameIOError, ReferenceMismatchError
from ..telecine.sequence import Sequence, discover
from .frames import FrameFacts, differences, facts_from_header, read_pixels
from .golden import NOISY_LAYER, Manifest, read_manifest
from .stats import ALPHA, FILTER_KAPPA, Region, compare_frame

Outcome = Literal["identical", "equal", "different", "missing"]
FlipMode = Literal["different", "all", "off"]
# frames per process below which a pool costs more than it saves
_POOL_MIN_FRAMES = 8


@dataclass
class FrameOutcome:
    """One frame's comparison: its number and files, the outcome, the test's figures, the
    regions that differ, the FLIP mean (None when not computed), which variant and seed made
    each frame, and the seconds it took."""

    frame: int
    new: str | None
    ref: str
    outcome: Outcome
    layer: str = "beauty"
    max_z: float = 0.0
    threshold: float = 0.0
    kappa: float = 1.0
    rms: dict[str, float] = field(default_factory=dict)
    max_abs: dict[str, float] = field(default_factory=dict)
    regions: list[Region] = field(default_factory=list)
    flip: float | None = None
    new_facts: dict[str, Any] = field(default_factory=dict)
    ref_facts: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    block: int = 8
    z_blocks: np.ndarray | None = None
    flip_map: np.ndarray | None = None

    @property
    def failed(self) -> bool:
        """Whether this frame fails the comparison (different or missing)."""
        return self.outcome in ("different", "missing")

    def message(self) -> str:
        """One line: the outcome and, for a difference, the region that differs most."""
        if self.outcome == "missing":
            return f"frame {self.frame}: missing from the new frames"
        if self.outcome == "identical":
            return f"frame {self.frame}: identical"
        if self.outcome == "equal":
            return f"frame {self.frame}: equal within noise (largest |z| {self.max_z:.1f} < {self.threshold:.1f})"
        worst = self.regions[0].describe() if self.regions else ""
        more = f" and {len(self.regions) - 1} more region(s)" if len(self.regions) > 1 else ""
        flip = f", FLIP {self.flip:.3f}" if self.flip is not None else ""
        return f"frame {self.frame}: different at {worst}{more}{flip}"

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the JSON report."""
        return {"frame": self.frame, "new": self.new, "ref": self.ref, "outcome": self.outcome, "layer": self.layer,
                "max_z": self.max_z, "threshold": self.threshold, "kappa": self.kappa, "rms": self.rms, "max_abs": self.max_abs,
                "regions": [r.__dict__ for r in self.regions], "flip": self.flip, "new_facts": self.new_facts, "ref_facts": self.ref_facts,
                "seconds": self.seconds, "message": self.message()}


@dataclass
class Comparison:
    """A whole comparison: the folders, each frame's outcome, the new frames no reference
    covers, the differences in how they were made that the user allowed, and the seconds."""

    new_dir: Path
    ref_dir: Path
    frames: list[FrameOutcome]
    unreferenced: list[int] = field(default_factory=list)
    allowed: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> list[FrameOutcome]:
        """The frames that fail."""
        return [f for f in self.frames if f.failed]

    @property
    def exit_code(self) -> int:
        """0 when every frame is identical or equal within noise, 1 otherwise."""
        return 1 if self.failed else 0

    def counts(self) -> dict[str, int]:
        """Frames per outcome."""
        out = {k: 0 for k in ("identical", "equal", "different", "missing")}
        for f in self.frames:
            out[f.outcome] += 1
        return out

    def summary(self) -> str:
        """The one-line summary."""
        c = self.counts()
        head = "FAIL" if self.failed else "PASS"
        parts = [f"{c['identical']} identical", f"{c['equal']} equal within noise", f"{c['different']} different"]
        if c["missing"]:
            parts.append(f"{c['missing']} missing")
        worst = ""
        if self.failed:
            w = max(self.failed, key=lambda f: (f.outcome == "different", f.max_z))
            worst = f"; worst {w.message()}"
        n = len(self.frames)
        return f"{head}: {n} frame{'' if n == 1 else 's'} of {self.new_dir} against {self.ref_dir}: {', '.join(parts)}{worst} ({self.seconds:.2f} s)"

    def variants(self) -> dict[str, list[int]]:
        """Which variant made which new frames (a mixed CPU/GPU farm, checked)."""
        out: dict[str, list[int]] = {}
        for f in self.frames:
            out.setdefault(str(f.new_facts.get("variant") or "unknown"), []).append(f.frame)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the JSON report."""
        return {"new": str(self.new_dir), "ref": str(self.ref_dir), "exit_code": self.exit_code, "summary": self.summary(), "counts": self.counts(),
                "unreferenced": self.unreferenced, "allowed_differences": self.allowed, "variants": self.variants(), "seconds": self.seconds,
                "frames": [f.to_dict() for f in self.frames]}


def compare_pair(number: int, new_path: str, ref_path: str, *, flip: FlipMode = "different", alpha: float = ALPHA, keep_maps: bool = False) -> FrameOutcome:
    """Read and test one pair of frames (what each pool process runs)."""
    t0 = time.perf_counter()
    (new_header, new_rgba, new_noisy), (ref_header, ref_rgba, ref_noisy) = read_pixels(new_path, NOISY_LAYER), read_pixels(ref_path, NOISY_LAYER)
    if new_rgba.shape != ref_rgba.shape:
        h, w = ref_rgba.shape[:2]
        raise ReferenceMismatchError(f"{new_path}: frame {number} is {new_rgba.shape[1]}x{new_rgba.shape[0]}, its reference {ref_path} is {w}x{h}: not comparable")
    use_noisy = new_noisy is not None and ref_noisy is not None and new_noisy.shape == ref_noisy.shape
    new_facts = facts_from_header(Path(new_path), new_header).to_dict()
    ref_facts = facts_from_header(Path(ref_path), ref_header).to_dict()
    test = compare_frame(new_noisy if use_noisy else new_rgba, ref_noisy if use_noisy else ref_rgba, alpha=alpha, kappa=filter_kappa(new_facts, ref_facts))  # type: ignore[arg-type]
    outcome = FrameOutcome(
        frame=number, new=new_path, ref=ref_path, outcome=test.verdict, layer=NOISY_LAYER if use_noisy else "beauty",
        max_z=test.max_z, threshold=test.threshold, kappa=test.kappa, rms=test.rms, max_abs=test.max_abs, regions=test.regions,
        new_facts=new_facts, ref_facts=ref_facts,
        block=test.block, z_blocks=test.z_blocks if keep_maps else None,
    )
    if flip == "all" or (flip == "different" and test.verdict == "different"):
        outcome.flip, fmap = flip_score(new_rgba, ref_rgba)
        if keep_maps:
            outcome.flip_map = fmap
    outcome.seconds = time.perf_counter() - t0
    return outcome


def filter_kappa(new_facts: dict[str, Any], ref_facts: dict[str, Any]) -> float | None:
    """The noise correlation factor of the frames' reconstruction filter when both headers
    name the same known one (stats.FILTER_KAPPA), else None (measured on the frame)."""
    names = {(f.get("settings") or {}).get("filter") for f in (new_facts, ref_facts)}
    if len(names) != 1:
        return None
    return FILTER_KAPPA.get(str(names.pop()))


def flip_score(new: np.ndarray, ref: np.ndarray) -> tuple[float, np.ndarray]:
    """HDR-FLIP (NVIDIA, `flip-evaluator`) of NEW against REF on the linear RGB beauty:
    the mean and the per-pixel map [H, W] in [0, 1]."""
    import flip_evaluator

    a = np.ascontiguousarray(np.clip(ref[..., :3], 0.0, None), dtype=np.float32)
    b = np.ascontiguousarray(np.clip(new[..., :3], 0.0, None), dtype=np.float32)
    fmap, mean, _params = flip_evaluator.evaluate(a, b, "HDR", applyMagma=False)
    return float(mean), np.asarray(fmap, dtype=np.float32).reshape(a.shape[:2])


def _check_made_alike(new_seq: Sequence, ref_seq: Sequence, manifest: Manifest | None, common: list[int], allow: bool) -> list[str]:
    """The differences in how the frames were made (refused unless `allow`)."""
    from .frames import frame_facts

    new_paths = dict(zip(new_seq.numbers, new_seq.paths))
    ref_paths = dict(zip(ref_seq.numbers, ref_seq.paths))
    found: list[str] = []
    for number in common:
        new_facts = frame_facts(new_paths[number]).to_dict()
        ref_facts = manifest.facts() if manifest is not None else frame_facts(ref_paths[number]).to_dict()
        for diff in differences(new_facts, ref_facts):
            if diff.startswith("resolution"):
                raise ReferenceMismatchError(f"{new_paths[number]}: {diff}: frames of different sizes cannot be compared")
            line = f"frame {number}: {diff}"
            if not allow:
                where = f"{ref_seq.directory / 'manifest.json'}" if manifest is not None else str(ref_paths[number])
                raise ReferenceMismatchError(f"{new_paths[number]} is not comparable with {where}: {diff} (--allow-different-settings compares anyway; --bless makes these frames the references)")
            if diff not in {d.split(': ', 1)[1] for d in found}:
                found.append(line)
    return found


def compare_sequences(
    new_dir: str | Path,
    ref_dir: str | Path,
    *,
    prefix: str | None = None,
    frames: list[int] | None = None,
    allow_different_settings: bool = False,
    flip: FlipMode = "different",
    alpha: float = ALPHA,
    workers: int | None = None,
    keep_maps: bool = False,
) -> Comparison:
    """Compare the sequence in `new_dir` with the references in `ref_dir` frame by frame.
    `frames`: only these frame numbers (default: every reference frame). Raises
    ReferenceMismatchError (exit 2) for frames not made alike unless allowed, FrameIOError
    for unreadable folders or frames."""
    t0 = time.perf_counter()
    manifest = read_manifest(ref_dir)
    ref_prefix = manifest.data.get("prefix") if manifest is not None else prefix
    ref_seq = discover(ref_dir, ref_prefix, require_even_height=False, allow_gaps=True)
    named = prefix or ref_seq.prefix
    new_seq = discover(new_dir, named if _has_prefix(new_dir, named) else prefix, require_even_height=False, allow_gaps=True)
    wanted = sorted(set(frames)) if frames is not None else list(ref_seq.numbers)
    absent_ref = [n for n in wanted if n not in ref_seq.numbers]
    if absent_ref:
        raise FrameIOError(f"{ref_dir}: no reference for frame {absent_ref[0]}" + (f" ({len(absent_ref)} frames have none)" if len(absent_ref) > 1 else ""))
    common = [n for n in wanted if n in new_seq.numbers]
    missing = [n for n in wanted if n not in new_seq.numbers]
    unreferenced = [n for n in new_seq.numbers if n not in ref_seq.numbers] if frames is None else []
    allowed = _check_made_alike(new_seq, ref_seq, manifest, common, allow_different_settings)

    new_paths = dict(zip(new_seq.numbers, map(str, new_seq.paths)))
    ref_paths = dict(zip(ref_seq.numbers, map(str, ref_seq.paths)))
    jobs = [(n, new_paths[n], ref_paths[n]) for n in common]
    workers = workers if workers is not None else min(2, os.cpu_count() or 1)
    outcomes: list[FrameOutcome]
    if workers > 1 and len(jobs) >= _POOL_MIN_FRAMES:
        import multiprocessing

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver")) as pool:
            futures = [pool.submit(compare_pair, n, a, b, flip=flip, alpha=alpha, keep_maps=keep_maps) for n, a, b in jobs]
            outcomes = [f.result() for f in futures]
    else:
        outcomes = [compare_pair(n, a, b, flip=flip, alpha=alpha, keep_maps=keep_maps) for n, a, b in jobs]
    outcomes += [FrameOutcome(frame=n, new=None, ref=ref_paths[n], outcome="missing") for n in missing]
    outcomes.sort(key=lambda o: o.frame)
    return Comparison(Path(new_dir), Path(ref_dir), outcomes, unreferenced, allowed, time.perf_counter() - t0)


def _has_prefix(folder: str | Path, prefix: str | None) -> bool:
    """Whether `folder` holds frames named `prefix`.NNNN.exr (the references' name is
    tried first in the new folder; a folder of one sequence under another name still
    compares)."""
    from ..telecine.sequence import find_sequences

    return prefix is not None and prefix in find_sequences(folder)


__all__ = ["Comparison", "FrameOutcome", "FrameFacts", "compare_pair", "compare_sequences", "flip_score"]
