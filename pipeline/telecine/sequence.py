"""EXR sequences on disk: discover `prefix.NNNN.exr` files, validate them before any work.

Telecine writes nothing until the whole input is known to be usable: every frame number
between the first and the last is present (only the contact sheet, a glance tool, accepts
gaps: `allow_gaps=True`, the absent numbers in `Sequence.missing`), every header reads, every frame has the same
size, and the height is even (a field pair needs as many bottom rows as top rows).
Each problem is a `FrameIOError` naming the offending frame.

This is the one reader of frame file names (`frame_number`, `frame_digits`): what the
renderer writes (`shot.-0002.exr` for a frame below 0, as scene/schema.py `frame_name`
does) every tool reads. Nothing here is sized by the span of the frame numbers (frames 0
and 2**31 are two frames): the absent numbers are kept as runs (`Gaps`), never listed.
"""

from __future__ import annotations

import os
import re
from collections import abc
from dataclasses import dataclass, field, replace
from fractions import Fraction
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Literal, Mapping, TypeVar, overload

import numpy as np

from ..errors import FrameIOError
from ..frame_output import Frame, check_data_window, motion_meta, read_frame, read_header
from ..timeline import format_frames, format_range

PixelType = Literal["half", "float"]

_NAME = re.compile(r"^(?P<prefix>.+)\.(?P<number>-?\d+)\.exr$", re.IGNORECASE)


def frame_number(name: str) -> tuple[str, int, int] | None:
    """`shot.0012.exr` -> ('shot', 12, 4), `shot.-0002.exr` -> ('shot', -2, 4): prefix,
    number and digits (the padding, without the sign); None for another name."""
    m = _NAME.match(name)
    if m is None:
        return None
    return m["prefix"], int(m["number"]), len(m["number"].lstrip("-"))


def frame_digits(number: int, padding: int = 4) -> str:
    """A frame number as it is written in a file name: 12 -> '0012', -2 -> '-0002' (the sign
    before `padding` digits, as the renderer names frames)."""
    return f"{number:0{padding}d}" if number >= 0 else f"-{-number:0{padding}d}"


@dataclass(frozen=True, eq=False)
class Gaps(abc.Sequence):  # type: ignore[type-arg]
    """The absent frame numbers between a sequence's first and last frame, held as runs
    (first, last) between the frames present: as long as the frames, however far apart
    their numbers are. It reads as the sequence of the numbers themselves (len, index,
    slice, `in`, iteration, truth, == a tuple), each computed when asked."""

    runs: tuple[tuple[int, int], ...] = ()

    @classmethod
    def between(cls, numbers: Iterable[int]) -> "Gaps":
        """The runs absent between sorted, distinct `numbers`."""
        ns = list(numbers)
        return cls(tuple((a + 1, b - 1) for a, b in zip(ns, ns[1:]) if b > a + 1))

    def __len__(self) -> int:
        return sum(b - a + 1 for a, b in self.runs)

    def __bool__(self) -> bool:
        return bool(self.runs)

    def __iter__(self) -> Iterator[int]:
        for a, b in self.runs:
            yield from range(a, b + 1)

    def __contains__(self, number: object) -> bool:
        return isinstance(number, int) and any(a <= number <= b for a, b in self.runs)

    @overload
    def __getitem__(self, index: int) -> int: ...
    @overload
    def __getitem__(self, index: slice) -> tuple[int, ...]: ...
    def __getitem__(self, index: int | slice) -> int | tuple[int, ...]:
        if isinstance(index, slice):
            return tuple(self[i] for i in range(*index.indices(len(self))))
        i = index + len(self) if index < 0 else index
        for a, b in self.runs:
            if 0 <= i <= b - a:
                return a + i
            i -= b - a + 1
        raise IndexError("Gaps index out of range")

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Gaps):
            return self.runs == other.runs
        return isinstance(other, (tuple, list)) and len(self) == len(other) and all(x == y for x, y in zip(self, other))

    def __hash__(self) -> int:
        return hash(self.runs)

    def __repr__(self) -> str:
        return f"Gaps({self.text()})"

    def text(self, limit: int = 8) -> str:
        """The absent numbers as runs in the `--frames` grammar ('3-5,9'), at most `limit`
        runs and then how many more."""
        runs = self.runs
        shown = ",".join(format_range(a, b) if b > a + 1 else format_frames([a, b]) for a, b in runs[:limit])
        return shown + (f" and {len(runs) - limit} more runs" if len(runs) > limit else "")


@dataclass(frozen=True)
class Sequence:
    """A validated EXR sequence: frame numbers in order, their paths, size and timing."""

    directory: Path
    prefix: str
    numbers: tuple[int, ...]
    paths: tuple[Path, ...]
    width: int
    height: int
    pixel_type: PixelType
    fps: Fraction | None = None
    first_meta: dict[str, Any] = field(default_factory=dict)
    missing: Gaps = Gaps()  # absent frame numbers between first and last, as runs (allow_gaps only)
    padding: int = 4  # digits of the frame number in names made from it (at least 4)

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def first(self) -> int:
        """The first frame number."""
        return self.numbers[0]

    def read(self, index: int) -> Frame:
        """Frame `index` (0-based position in the sequence), pixels as float32."""
        return read_frame(self.paths[index])

    def frames(self) -> Iterator[Frame]:
        """Every frame read in order (pixels, layers and metadata)."""
        for path in self.paths:
            yield read_frame(path)


def _size(path: Path, header: dict[str, Any]) -> tuple[int, int]:
    try:
        lo, hi = header["dataWindow"]
        return int(hi[0]) - int(lo[0]) + 1, int(hi[1]) - int(lo[1]) + 1
    except (KeyError, TypeError, ValueError, IndexError):
        raise FrameIOError(f"{path}: header has no usable dataWindow") from None


def _pixel_type(path: Path) -> PixelType:
    """'half' when the colour channels are stored as 16-bit floats, else 'float'."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path)) as f:
            dtypes = {np.asarray(ch.pixels).dtype for ch in f.channels().values()}
    except Exception as exc:
        raise FrameIOError(f"{path}: not a readable OpenEXR file ({exc})") from None
    return "half" if np.dtype(np.float16) in dtypes else "float"


def find_sequences(directory: str | Path) -> dict[str, list[tuple[int, Path]]]:
    """All `prefix.NNNN.exr` files of a folder, grouped by prefix and sorted by number."""
    directory = Path(directory)
    if not directory.is_dir():
        raise FrameIOError(f"{directory}: no such folder")
    groups: dict[str, list[tuple[int, Path]]] = {}
    for path in directory.iterdir():
        found = frame_number(path.name)
        if found and not path.name.startswith("."):
            groups.setdefault(found[0], []).append((found[1], path))
    for items in groups.values():
        items.sort()
    return groups


def choose_sequence(directory: Path, prefix: str | None = None) -> tuple[str, list[tuple[int, Path]]]:
    """(prefix, [(frame number, file)]) of the `prefix`.NNNN.exr sequence in `directory`, or
    of the only one there when `prefix` is None. FrameIOError for a folder without it or with
    several sequences (the message says to choose one with --prefix)."""
    groups = find_sequences(directory)
    if prefix is not None:
        if prefix not in groups:
            raise FrameIOError(f"{directory}: no frames named {prefix}.NNNN.exr")
        return prefix, groups[prefix]
    if not groups:
        raise FrameIOError(f"{directory}: no EXR sequence (expected files named prefix.NNNN.exr)")
    if len(groups) > 1:
        found = ", ".join(f"{p} ({len(v)} frames)" for p, v in sorted(groups.items()))
        raise FrameIOError(f"{directory}: several EXR sequences ({found}); choose one with --prefix")
    return next(iter(groups.items()))


def discover(
    directory: str | Path,
    prefix: str | None = None,
    *,
    require_even_height: bool = True,
    min_frames: int = 1,
    allow_gaps: bool = False,
) -> Sequence:
    """Find and validate the EXR sequence in `directory` (the only one, or `prefix`).

    Reads every header (not the pixels) so a missing, foreign or truncated-header frame is
    reported before anything is written. Raises FrameIOError naming the frame. With
    `allow_gaps` absent frame numbers are not an error; they are listed in `missing`.
    """
    directory = Path(directory)
    prefix, items = choose_sequence(directory, prefix)

    numbers = [n for n, _ in items]
    dup = next((a for a, b in zip(numbers, numbers[1:]) if a == b), None)  # (sorted: a repeat is adjacent)
    if dup is not None:
        names = [p.name for n, p in items if n == dup]
        raise FrameIOError(f"{directory}: frame {dup} appears twice ({', '.join(names)})")
    pad = frame_number(items[0][1].name)[2]  # type: ignore[index]
    missing = Gaps.between(numbers)
    if missing and not allow_gaps:
        shown = ", ".join(str(directory / f"{prefix}.{frame_digits(n, pad)}.exr") for n in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise FrameIOError(f"missing frame {shown}{more} in sequence {prefix} ({format_range(numbers[0], numbers[-1])})")
    if len(items) < min_frames:
        raise FrameIOError(f"{directory}: sequence {prefix} has {len(items)} frames, need at least {min_frames}")
    return sequence_of(dict(items), prefix, directory=directory, require_even_height=require_even_height, padding=max(4, pad))


def sequence_of(
    frames: Mapping[int, str | Path],
    prefix: str,
    *,
    directory: str | Path | None = None,
    require_even_height: bool = True,
    padding: int = 4,
) -> Sequence:
    """A validated Sequence of the frames given by number (whatever their file names: the
    numbers travel with the paths, never parsed back from the names), in number order.

    Reads every header (not the pixels): a missing, foreign or truncated-header frame, a
    frame of another size or an odd height (when `require_even_height`) is a FrameIOError
    naming it. Absent numbers between the first and the last are listed in `missing`.
    """
    if not frames:
        raise FrameIOError(f"{directory or '.'}: no frames of sequence {prefix}")
    items = sorted((int(n), Path(p)) for n, p in frames.items())
    numbers = [n for n, _ in items]
    size: tuple[int, int] | None = None
    fps: Fraction | None = None
    first_meta: dict[str, Any] = {}
    for number, path in items:
        header = read_header(path)
        check_data_window(path, header)
        this = _size(path, header)
        if size is None:
            size = this
            rate = header.get("framesPerSecond")
            try:
                fps = Fraction(rate) if rate is not None else None
                if fps is not None and not 0 < fps <= 100_000:
                    raise ValueError(f"{fps} is out of range")
            except (TypeError, ValueError, ZeroDivisionError):
                raise FrameIOError(f"{path}: framesPerSecond {rate!r} is not a frame rate") from None
            first_meta = motion_meta(header)
            if require_even_height and this[1] % 2:
                raise FrameIOError(
                    f"{path}: odd height {this[1]}; interlaced fields need an even number of rows"
                )
        elif this != size:
            raise FrameIOError(
                f"{path}: resolution {this[0]}x{this[1]} differs from the sequence's "
                f"{size[0]}x{size[1]} (first frame {items[0][1].name})"
            )
    width, height = size if size is not None else (0, 0)
    return Sequence(
        directory=Path(directory) if directory is not None else items[0][1].parent,
        prefix=prefix,
        numbers=tuple(numbers),
        paths=tuple(p for _, p in items),
        width=width,
        height=height,
        pixel_type=_pixel_type(items[0][1]),
        fps=fps,
        first_meta=first_meta,
        missing=Gaps.between(numbers),
        padding=padding,
    )


def select(seq: Sequence, numbers: list[int] | tuple[int, ...]) -> Sequence:
    """The frames `numbers` of `seq`, in that order (what a run selected, not every frame
    of its folder). FrameIOError naming the first absent frame."""
    where = dict(zip(seq.numbers, seq.paths))
    absent = [n for n in numbers if n not in where]
    if absent:
        raise FrameIOError(f"{seq.directory}: frame {absent[0]} of sequence {seq.prefix} is not there" + (f" ({len(absent)} absent)" if len(absent) > 1 else ""))
    return replace(seq, numbers=tuple(numbers), paths=tuple(where[n] for n in numbers), missing=Gaps())


T = TypeVar("T")


def assembly_threads() -> int:
    """Threads that read and transform frames for a deliverable: the cores this process may
    use ($MOTION_ASSEMBLY_THREADS overrides), at most 16. OpenEXR's decoder and OpenColorIO's
    CPU processor run outside Python's lock, so frames are read and viewed side by side
    while the encoder takes them in order."""
    env = os.environ.get("MOTION_ASSEMBLY_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return min(int(env), 64)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # (not on Linux)
        cores = os.cpu_count() or 1
    return max(1, min(cores, 16))


def read_mapped(seq: Sequence, fn: Callable[[Frame], T], indices: Iterable[int] | None = None, threads: int | None = None) -> Iterator[T]:
    """`fn(frame)` of each frame (checked as read_checked does) in order, computed by a few
    threads at most 2 x threads frames ahead of the consumer (so memory stays bounded)."""
    order = list(range(len(seq)) if indices is None else indices)
    workers = threads or assembly_threads()
    if workers == 1 or len(order) < 2:
        for i in order:
            yield fn(read_checked(seq, i))
        return
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="assemble") as pool:
        pending: deque = deque()
        it = iter(order)
        try:
            for i in it:
                pending.append(pool.submit(lambda k: fn(read_checked(seq, k)), i))
                if len(pending) >= 2 * workers:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for fut in pending:
                fut.cancel()


def read_checked(seq: Sequence, index: int) -> Frame:
    """Read frame `index` and check it still matches the sequence (size), naming the file."""
    frame = seq.read(index)
    h, w = frame.rgba.shape[:2]
    if (w, h) != (seq.width, seq.height):
        raise FrameIOError(f"{seq.paths[index]}: resolution {w}x{h} differs from the sequence's {seq.width}x{seq.height}")
    return frame
