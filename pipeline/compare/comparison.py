"""`motion compare NEW REF`: two EXR sequences, frame by frame (docs/compare.md).

Frames pair by number; a golden set's references are only the files its manifest lists.
Each pair's headers are read first: frames of other sizes cannot be compared (exit 2
before any pixel is read); how else they were made differently (a material, a setting, the
motion: frames.notes) is compared all the same and named as a note. Each pair is then read
(frames.read_pixels) and tested (stats.compare_frame) on the noisy beauty when both
frames keep one (a denoiser's output has no per-pixel noise left to measure), else on the
beauty. A frame that differs gets a perceptual score: NVIDIA's FLIP (`flip-evaluator`,
HDR-FLIP on the linear beauty), its mean and the FLIP map for the report.

Frames are tested in a pool of processes (two on two cores) when there are many; Ctrl-C or
SIGTERM stops the pool's processes at once.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Literal, Mapping

import numpy as np

from ..errors import FrameIOError, ReferenceMismatchError
from ..timeline import format_frames
from .frames import FrameFacts, facts_from_header, find_frames, frame_facts, incomparable, notes, read_pixels
from .golden import NOISY_LAYER, read_manifest
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
    notes: list[str] = field(default_factory=list)  # how this frame and its reference were made differently

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
                "seconds": self.seconds, "message": self.message(), "notes": self.notes}


@dataclass
class Comparison:
    """A whole comparison: the folders, each frame's outcome, the new frames no reference
    covers, the notes (how the frames were made differently from their references, each
    with the frames it concerns: `frames 11-13: material 2 of the scene (m1) differs`), and
    the seconds."""

    new_dir: Path
    ref_dir: Path
    frames: list[FrameOutcome]
    unreferenced: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
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
                "unreferenced": self.unreferenced, "notes": self.notes, "allowed_differences": self.notes, "variants": self.variants(), "seconds": self.seconds,
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


# the input that ACES maps to its largest output, FLIP's own `x_max` (its start exposure is
# log2(x_max / the reference's largest luminance))
_FLIP_X_MAX = 2.1188731966890900
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> Y


def flip_score(new: np.ndarray, ref: np.ndarray) -> tuple[float, np.ndarray]:
    """HDR-FLIP (NVIDIA, `flip-evaluator`) of NEW against REF on the linear RGB beauty:
    the mean and the per-pixel map [H, W] in [0, 1]. Non-finite values count as 0 here
    (the test names them). FLIP sets its exposure range from the reference's largest and
    median luminance and ends the process when the two meet (a black or uniform reference):
    the range is then one stop up to the exposure that maps the brighter frame's largest
    luminance to the top."""
    import flip_evaluator

    def linear(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.clip(np.nan_to_num(x[..., :3], nan=0.0, posinf=0.0, neginf=0.0), 0.0, None), dtype=np.float32)

    a, b = linear(ref), linear(new)
    y = a.astype(np.float64) @ _LUMINANCE
    y_max, y_median = float(y.max(initial=0.0)), float(np.median(y)) if y.size else 0.0
    params: dict[str, Any] = {}
    if not y_max > y_median * (1.0 + 1e-4):
        bright = y_max if y_max > 0 else float((b.astype(np.float64) @ _LUMINANCE).max(initial=0.0))
        exposure = float(np.log2(_FLIP_X_MAX / bright)) if bright > 0 else 0.0
        params = {"startExposure": exposure - 1.0, "stopExposure": exposure, "numExposures": 2}
    fmap, mean, _params = flip_evaluator.evaluate(a, b, "HDR", applyMagma=False, parameters=params)
    return float(mean), np.asarray(fmap, dtype=np.float32).reshape(a.shape[:2])


def frame_notes(new_paths: dict[int, Path], ref_paths: dict[int, Path], common: list[int], names: Mapping[str, str] | None = None) -> dict[int, list[str]]:
    """Each common frame's notes (frames.notes) from the two headers; ReferenceMismatchError
    (exit 2) for a pair that cannot be compared (frames.incomparable), before any pixel."""
    out: dict[int, list[str]] = {}
    for number in common:
        new_facts = frame_facts(new_paths[number]).to_dict()
        ref_facts = frame_facts(ref_paths[number]).to_dict()
        cannot = incomparable(new_facts, ref_facts)
        if cannot:
            raise ReferenceMismatchError(f"{new_paths[number]}: {cannot[0]} of reference {ref_paths[number]}: frames of different sizes cannot be compared")
        out[number] = notes(new_facts, ref_facts, names)
    return out


def gather_notes(per_frame: dict[int, list[str]]) -> list[str]:
    """One line per note with the frames it concerns, in first-seen order."""
    frames: dict[str, list[int]] = {}
    for number in sorted(per_frame):
        for note in per_frame[number]:
            frames.setdefault(note, []).append(number)
    return [f"frame{'s' if len(f) > 1 else ''} {format_frames(f)}: {note}" for note, f in frames.items()]


def reference_frames(ref_dir: str | Path, prefix: str | None) -> tuple[str | None, dict[int, Path]]:
    """(name, {frame: file}) of the references: a golden set's manifest lists them (every
    file checked against its digest; a file it does not list is no reference), else the
    folder's sequence."""
    manifest = read_manifest(ref_dir)
    if manifest is not None:
        return manifest.data.get("prefix"), manifest.paths()
    return find_frames(ref_dir, prefix)


def compare_sequences(
    new_dir: str | Path,
    ref_dir: str | Path,
    *,
    prefix: str | None = None,
    frames: list[int] | None = None,
    flip: FlipMode = "different",
    alpha: float = ALPHA,
    workers: int | None = None,
    keep_maps: bool = False,
    part_names: Mapping[str, str] | None = None,
) -> Comparison:
    """Compare the sequence in `new_dir` with the references in `ref_dir` frame by frame.
    `frames`: only these frame numbers (default: every reference frame); `part_names`: what
    the look's parts are called in the new frames' scene (for the notes). Raises
    ReferenceMismatchError (exit 2) for frames of other sizes, FrameIOError for unreadable
    folders, frames or manifests; frames made differently are compared and noted."""
    t0 = time.perf_counter()
    ref_name, ref_paths = reference_frames(ref_dir, prefix)
    named = prefix or ref_name
    _, new_paths = find_frames(new_dir, named if _has_prefix(new_dir, named) else prefix)
    wanted = sorted(set(frames)) if frames is not None else sorted(ref_paths)
    absent_ref = [n for n in wanted if n not in ref_paths]
    if absent_ref:
        raise FrameIOError(f"{ref_dir}: no reference for frame {absent_ref[0]}" + (f" ({len(absent_ref)} frames have none)" if len(absent_ref) > 1 else ""))
    common = [n for n in wanted if n in new_paths]
    missing = [n for n in wanted if n not in new_paths]
    unreferenced = sorted(n for n in new_paths if n not in ref_paths) if frames is None else []
    per_frame = frame_notes(new_paths, ref_paths, common, part_names)
    jobs = [(n, str(new_paths[n]), str(ref_paths[n])) for n in common]
    workers = workers if workers is not None else min(2, os.cpu_count() or 1)
    outcomes: list[FrameOutcome]
    if workers > 1 and len(jobs) >= _POOL_MIN_FRAMES:
        outcomes = _in_pool(jobs, workers, flip=flip, alpha=alpha, keep_maps=keep_maps)
    else:
        outcomes = [compare_pair(n, a, b, flip=flip, alpha=alpha, keep_maps=keep_maps) for n, a, b in jobs]
    for outcome in outcomes:
        outcome.notes = per_frame.get(outcome.frame, [])
    outcomes += [FrameOutcome(frame=n, new=None, ref=str(ref_paths[n]), outcome="missing") for n in missing]
    outcomes.sort(key=lambda o: o.frame)
    return Comparison(Path(new_dir), Path(ref_dir), outcomes, unreferenced, gather_notes(per_frame), time.perf_counter() - t0)


def _quiet_worker() -> None:
    """A pool process leaves Ctrl-C to the command, which stops it (no traceback per process)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _in_pool(jobs: list[tuple[int, str, str]], workers: int, **options: Any) -> list[FrameOutcome]:
    """compare_pair of every job in `workers` processes. On Ctrl-C, SIGTERM (cli/main.py
    raises KeyboardInterrupt for it) or an error, the processes are ended at once and
    nothing waits for the frames in flight."""
    import multiprocessing

    with _stops_held() as stops:
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("forkserver"), initializer=_quiet_worker)
        try:
            futures = [pool.submit(compare_pair, n, a, b, **options) for n, a, b in jobs]
            outcomes = [_awaited(f, stops) for f in futures]
        except BaseException:
            _end(pool)
            raise  # (a stop: _stops_held raises it as KeyboardInterrupt on the way out)
        pool.shutdown(wait=True)
    return outcomes


class _Stopped(BaseException):
    """A stop came while the pool ran (its KeyboardInterrupt follows: `_stops_held`)."""


def _awaited(future: Any, stops: list[int]) -> Any:
    """The future's result, looking every quarter second for a stop (`_stops_held`)."""
    while not stops:
        try:
            return future.result(timeout=0.25)
        except TimeoutError:
            if future.done():  # the job's own TimeoutError
                raise
    raise _Stopped


@contextlib.contextmanager
def _stops_held() -> Iterator[list[int]]:
    """Ctrl-C and SIGTERM only noted while a pool runs (the list it yields gets the signal);
    on the way out the handlers are put back and a stop that came goes to its own
    (KeyboardInterrupt), from here. Raised wherever the main thread happened to be, the
    stop landed now in a process's hand-over to the forkserver (children that printed
    tracebacks: the forkserver's EOFError, a semaphore already gone), now nowhere: the
    main thread slept on in its wait for a frame and the compare went on (about 1 stop in
    40 on a loaded host, past the test's 30 s). Outside the main thread (no handlers
    there) nothing is noted."""
    import signal

    came: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield came
        return

    def note(signum: int, frame: Any) -> None:
        came.append(signum)

    # a signal the process ignores (a SIGINT nohup or a background shell left ignored)
    # stays ignored
    previous = {s: h for s in (signal.SIGINT, signal.SIGTERM) if (h := signal.getsignal(s)) is not signal.SIG_IGN}
    try:
        for s in previous:
            signal.signal(s, note)
        yield came
    finally:
        for s, handler in previous.items():
            if handler is not None:  # (None: a handler not set from Python, left as it is)
                signal.signal(s, handler)
        if came:
            signal.raise_signal(came[0])


def _end(pool: ProcessPoolExecutor) -> None:
    """End a pool at once: its processes terminated, its manager thread released."""
    # the executor has no public way to end its processes, and its shutdown drops the
    # references to them and to its manager thread: both are taken first
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=5)
    if manager is not None:
        _release_manager(manager)


def _release_manager(manager: threading.Thread) -> None:
    """Wait for a stopped pool's manager thread and take it off the interpreter's exit hook.

    The manager thread closes its wake-up pipe once it sees the processes gone, while
    concurrent.futures' exit hook writes to that pipe without the lock that guards the
    close (CPython 3.11): a "Bad file descriptor" traceback at exit, now and then on a busy
    host. The processes are ended, so the manager has nothing left to be woken for; with
    its entry gone the hook cannot race it."""
    from concurrent.futures import process as pool_internals

    manager.join(timeout=5)
    wakeups = getattr(pool_internals, "_threads_wakeups", None)
    if wakeups is not None:
        wakeups.pop(manager, None)


def _has_prefix(folder: str | Path, prefix: str | None) -> bool:
    """Whether `folder` holds frames named `prefix`.NNNN.exr (the references' name is
    tried first in the new folder; a folder of one sequence under another name still
    compares)."""
    from ..telecine.sequence import find_sequences

    return prefix is not None and prefix in find_sequences(folder)


__all__ = ["Comparison", "FrameOutcome", "FrameFacts", "compare_pair", "compare_sequences", "flip_score"]
