"""EXR sequence -> EXR sequence: pulldown (telecine) and its inverse, with honest metadata.

Output frames are written into a hidden staging folder inside the destination and moved
into place only once every frame has been written, so an error (a frame that fails to
read half-way) leaves the destination as it was.

Metadata on every telecined frame (besides the source frame's own `motion:` attributes):
`framesPerSecond` (rational video rate), `timeCode` (drop-frame on request), and
`motion:fieldOrder`, `motion:cadence`, `motion:cadenceCounts`, `motion:filmSpeed`,
`motion:topFieldSource`, `motion:bottomFieldSource`, `motion:firstFieldSource`,
`motion:secondFieldSource` (input frame numbers), `motion:videoFrame`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import FrameIOError, UsageError
from ..write_policy import publish_path, staging
from ..frame_output import Frame, read_meta, write_frame
from ..timeline import timecode
from .cadence import Cadence, Tail, film_rate, output_rate, parse_cadence, plan
from ..field_model import FieldOrder, check_field_order, weave_frames
from .inverse import Detection, detect_pulldown, recovery_map
from .sequence import Sequence, assembly_threads, discover, find_sequences, frame_digits, read_checked, read_mapped

if TYPE_CHECKING:
    from .movie import ViewedFrames

Progress = Callable[[int, int], None]

# Our attributes: stripped from the source frame's metadata before ours are added.
TELECINE_KEYS = (
    "fieldOrder", "cadence", "cadenceCounts", "filmSpeed", "topFieldSource", "bottomFieldSource",
    "firstFieldSource", "secondFieldSource", "videoFrame", "blendSources", "tail",
    "inverseTelecine", "cadencePhase", "topFieldFrom", "bottomFieldFrom",
)


@dataclass(frozen=True)
class SequenceOutput:
    """How a conversion reads its input's name and writes its frames, the same for pulldown
    and its inverse: the input sequence's `prefix` (None: the folder's only one), the
    output's `out_prefix` (None: the input's), the EXR `pixel_type` (None: the input's) and
    `compression`, whether an existing output sequence is replaced (`overwrite`), and
    `progress(done, total)` after each frame."""

    prefix: str | None = None
    out_prefix: str | None = None
    pixel_type: str | None = None
    compression: str = "zip"
    overwrite: bool = False
    progress: Progress | None = None

    def name(self, seq: Sequence) -> str:
        """The output sequence's prefix."""
        return self.out_prefix or seq.prefix

    def pixel_type_for(self, seq: Sequence) -> str:
        """The output frames' pixel type."""
        return self.pixel_type or seq.pixel_type


@dataclass(frozen=True)
class Result:
    """What a conversion wrote: the frames (in order), their rate, and how they were made."""

    out_dir: Path
    paths: tuple[Path, ...]
    rate: Fraction
    film_rate: Fraction
    cadence: Cadence
    field_order: FieldOrder | None
    detection: Detection | None = None


class _FrameCache:
    """The last few frames read; pulldown reads each source at most twice in a row. With
    `ahead` (the source indices in the order they will be asked for, ascending), the frames
    are read by a few threads ahead of their use (sequence.read_mapped)."""

    def __init__(self, seq: Sequence, size: int = 3, ahead: list[int] | None = None, shared: ViewedFrames | None = None) -> None:
        self.seq, self.size, self.shared = seq, size, shared
        self.frames: dict[int, Frame] = {}
        # with `shared` (a run's deliverables' viewed frames), each frame read is viewed in the same thread, once for the run
        view = shared.view if shared is not None and ahead and shared.used < shared.budget and any(i not in shared.kept for i in ahead) else None
        fn: Callable[[Frame], tuple[Frame, Any]] = (lambda frame: (frame, view(frame.rgba))) if view is not None else (lambda frame: (frame, None))
        self.coming = iter(zip(ahead, read_mapped(seq, fn, ahead))) if ahead else None

    def __call__(self, index: int) -> Frame:
        while index not in self.frames:
            if len(self.frames) >= self.size:
                self.frames.pop(min(self.frames))
            got = next(self.coming, None) if self.coming is not None else None
            if got is None:  # (not among those read ahead)
                self.frames[index] = read_checked(self.seq, index)
            else:
                (number, (frame, rgb16)) = got
                self.frames[number] = frame
                if rgb16 is not None:
                    self.shared.keep(number, rgb16)  # type: ignore[union-attr]
        return self.frames[index]


class _Writes:
    """Frames written by a few threads (OpenEXR compresses outside Python's lock), at most
    2 x threads in flight; `wait()` raises the first write's error."""

    def __init__(self) -> None:
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        self.threads = assembly_threads()
        self.pool = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="write")
        self.pending: Any = deque()

    def submit(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        """Write in the background (waiting for the oldest write when enough are in flight)."""
        self.pending.append(self.pool.submit(fn, *args, **kwargs))
        if len(self.pending) >= 2 * self.threads:
            self.pending.popleft().result()

    def wait(self) -> None:
        """Every write finished (the first error raised)."""
        try:
            while self.pending:
                self.pending.popleft().result()
        finally:
            self.pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "_Writes":
        return self

    def __exit__(self, *exc: Any) -> None:
        # on an error, writes not started are dropped and running ones end before the
        # staging folder goes; otherwise every write's error is raised here
        if exc[0] is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
        else:
            self.wait()


def _strip(meta: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in meta.items() if k not in TELECINE_KEYS}


def _weave_layers(top: Frame, bottom: Frame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    rgba = weave_frames(top.rgba, bottom.rgba)
    aovs = {name: weave_frames(layer, bottom.aovs[name]) for name, layer in top.aovs.items() if name in bottom.aovs}
    return rgba, aovs


def _blend_layers(a: Frame, b: Frame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    if a is b:
        return a.rgba, dict(a.aovs)
    mix = lambda x, y: ((x.astype(np.float32) + y.astype(np.float32)) * np.float32(0.5))  # noqa: E731
    return mix(a.rgba, b.rgba), {n: mix(v, b.aovs[n]) for n, v in a.aovs.items() if n in b.aovs}


class _Staging:
    """The output sequence of a conversion, written into a hidden folder inside `out_dir`
    (the write policy's `write_policy.staging`) one frame at a time (`write`: named, typed and
    compressed as `out` says, progress after each); `publish` moves the frames into
    `out_dir` (write_policy.publish_path) and removes the old sequence's others."""

    def __init__(self, out_dir: Path, seq: Sequence, out: SequenceOutput, total: int) -> None:
        prefix = out.name(seq)
        existing = find_sequences(out_dir).get(prefix, []) if out_dir.is_dir() else []
        if existing and not out.overwrite:
            raise UsageError(
                f"{out_dir} already holds {len(existing)} frames named {prefix}.NNNN.exr; "
                "use --overwrite to replace them"
            )
        self.out_dir, self.prefix, self.seq, self.out, self.total = out_dir, prefix, seq, out, total
        self.pixel_type = out.pixel_type_for(seq)
        self.names: list[str] = []
        self.old = [p for _, p in existing]
        self._folder = staging(out_dir, "writing the telecine frames in", prefix=".telecine-")
        self.dir = Path()

    def __enter__(self) -> "_Staging":
        self.dir = self._folder.__enter__()
        return self

    def write(
        self, number: int, rgba: np.ndarray, meta: dict[str, Any], aovs: dict[str, np.ndarray], *,
        fps: Fraction, timecode: str, submit: Callable[..., Any] | None = None,
    ) -> None:
        """Stage frame `number` of the output sequence (padded as the input's), written now or
        through `submit` (a background writer's), then report progress."""
        name = f"{self.prefix}.{frame_digits(number, self.seq.padding)}.exr"
        args = (self.dir / name, rgba, meta)
        options = dict(fps=fps, timecode=timecode, aovs=aovs or None, pixel_type=self.pixel_type, compression=self.out.compression)
        if submit is None:
            write_frame(*args, **options)  # type: ignore[arg-type]
        else:
            submit(write_frame, *args, **options)
        self.names.append(name)
        if self.out.progress:
            self.out.progress(len(self.names), self.total)

    def publish(self) -> tuple[Path, ...]:
        """Move the staged frames into the output folder; the old sequence's frames that are
        not among them go."""
        names = self.names
        keep = set(names)
        for path in self.old:
            if path.name not in keep:
                path.unlink(missing_ok=True)
        out = []
        for name in names:
            publish_path(self.dir / name, self.out_dir / name)
            out.append(self.out_dir / name)
        return tuple(out)

    def __exit__(self, *exc: Any) -> bool | None:
        return self._folder.__exit__(*exc)


def _check_dirs(in_dir: Path, out_dir: Path, in_prefix: str, out_prefix: str) -> None:
    if in_dir.resolve() == out_dir.resolve() and in_prefix == out_prefix:
        raise UsageError(f"output folder {out_dir} is the input folder; choose another -o or --out-prefix")


def _timecode(i: int, rate: Fraction, drop_frame: bool) -> str:
    try:
        return timecode(i, rate, drop_frame)
    except ValueError as exc:
        raise UsageError(f"--drop-frame: {exc} (video rate is {rate})") from None


def telecine_sequence(
    in_dir: str | Path,
    out_dir: str | Path,
    *,
    pattern: str | Cadence = "3:2",
    field_order: str = "tff",
    film_speed: str | Fraction | int = "23.976",
    tail: Tail = "pad",
    drop_frame: bool = False,
    sequence: Sequence | None = None,
    shared: ViewedFrames | None = None,
    output: SequenceOutput = SequenceOutput(),
    **output_fields: Any,
) -> Result:
    """Pull a progressive EXR sequence down to interlaced (or, for `blend`, blended) frames
    (`shared`: the run's deliverables' viewed frames, filled as the film frames are read;
    `output`, or its fields as keywords: how the frames are named and written).

    Video frame i is numbered `first + i`, where `first` is the input's first frame
    number. Its timecode continues the film's: the film's first frame number, counted at
    the film's nominal rate, is a time (frame 1001 at 24 is 41 s 17 frames), and video frame
    0 is that time counted at the video's nominal rate, rounded down (frame 1251 at 30 for
    3:2, 00:00:41:21); 00:00:00:00 for a film starting at frame 0.
    """
    cadence = parse_cadence(pattern) if isinstance(pattern, str) else pattern
    order = check_field_order(field_order)
    film = film_rate(film_speed)
    rate = output_rate(film, cadence)
    out = replace(output, **output_fields)
    in_dir, out_dir = Path(in_dir), Path(out_dir)
    seq = sequence or discover(in_dir, out.prefix, require_even_height=not cadence.blend)
    _check_dirs(seq.directory, out_dir, seq.prefix, out.name(seq))
    frames = plan(len(seq), cadence, order, tail)
    if drop_frame:
        _timecode(0, rate, True)
    start = max(0, seq.first) * round(rate) // max(1, round(film))  # the film's start, in video frames
    load = _FrameCache(seq, ahead=sorted({k for vf in frames for k in (vf.top, vf.bottom, vf.first, vf.second)}), shared=shared)
    with _Staging(out_dir, seq, out, len(frames)) as staging:
        with _Writes() as writes:
            for i, vf in enumerate(frames):
                top, bottom = load(vf.top), load(vf.bottom)
                meta = _strip(load(vf.first).meta)
                if cadence.blend:
                    rgba, aovs = _blend_layers(load(vf.first), load(vf.second))
                    meta["blendSources"] = f"{seq.numbers[vf.first]},{seq.numbers[vf.second]}"
                    meta["fieldOrder"] = "progressive"
                else:
                    rgba, aovs = _weave_layers(top, bottom)
                    meta.update(
                        fieldOrder=order,
                        topFieldSource=seq.numbers[vf.top],
                        bottomFieldSource=seq.numbers[vf.bottom],
                        firstFieldSource=seq.numbers[vf.first],
                        secondFieldSource=seq.numbers[vf.second],
                    )
                meta.update(
                    cadence=cadence.name,
                    cadenceCounts=":".join(str(c) for c in cadence.counts),
                    filmSpeed=film,
                    videoFrame=i,
                    tail=tail,
                )
                staging.write(seq.first + i, rgba, meta, aovs, fps=rate, timecode=_timecode(start + i, rate, drop_frame), submit=writes.submit)
        paths = staging.publish()
    return Result(out_dir, paths, rate, film, cadence, None if cadence.blend else order)


def read_header_meta(seq: Sequence, index: int) -> dict[str, Any]:
    """Our `motion:` attributes of frame `index` of a sequence."""
    return read_meta(seq.paths[index])


def _sources_from_metadata(seq: Sequence, order: FieldOrder) -> list[int] | None:
    """Film frame numbers of every field, from our own metadata; None if any frame lacks it."""
    sources: list[int] = []
    for i in range(len(seq)):
        meta = read_header_meta(seq, i)
        if "topFieldSource" not in meta or "bottomFieldSource" not in meta:
            return None
        try:
            top, bottom = int(meta["topFieldSource"]), int(meta["bottomFieldSource"])
        except (TypeError, ValueError, OverflowError):
            raise FrameIOError(f"{seq.paths[i]}: field sources {meta['topFieldSource']!r}, {meta['bottomFieldSource']!r} are not frame numbers") from None
        sources += [top, bottom] if order == "tff" else [bottom, top]
    return sources


def _field_sources(seq: Sequence, order: FieldOrder, pattern: str | Cadence | None, tolerance: float,
                   use_metadata: bool) -> tuple[list[int], Detection | None]:
    """The film frame of every field, in field order: from our metadata when every frame
    has it and no pattern is forced (detection None), else detected over `pattern`."""
    sources = _sources_from_metadata(seq, order) if (use_metadata and pattern is None) else None
    if sources is not None:
        return sources, None
    frames = (read_checked(seq, i).rgba for i in range(len(seq)))
    sources, detection = detect_pulldown(frames, len(seq), order, pattern, tolerance)
    if detection.violations:
        raise FrameIOError(
            f"{seq.directory}: sequence {seq.prefix} does not follow {detection.cadence.name} "
            f"pulldown ({detection.violations} fields that should repeat differ); "
            "give --pattern, or --tolerance for a lossy source"
        )
    return sources, detection


def _recovered_film_rate(seq: Sequence, cadence: Cadence, film_speed: str | Fraction | int | None) -> Fraction:
    """The recovered film's rate: the one asked for, else the frames' `motion:filmSpeed`,
    else their video rate over the cadence's ratio, else 23.976."""
    if film_speed is not None:
        return film_rate(film_speed)
    if isinstance(seq.first_meta.get("filmSpeed"), Fraction):
        return seq.first_meta["filmSpeed"]  # type: ignore[no-any-return]
    if seq.fps is not None:
        return seq.fps / cadence.rate_ratio
    return film_rate("23.976")


def inverse_sequence(
    in_dir: str | Path,
    out_dir: str | Path,
    *,
    pattern: str | Cadence | None = None,
    field_order: str | None = None,
    film_speed: str | Fraction | int | None = None,
    tolerance: float = 0.0,
    use_metadata: bool = True,
    output: SequenceOutput = SequenceOutput(),
    **output_fields: Any,
) -> Result:
    """Recover the progressive film frames from an interlaced EXR sequence.

    Which film frame fed each field comes from our metadata (`motion:topFieldSource` ...)
    when every frame has it and no pattern is forced; otherwise from detection over
    `pattern` (or 3:2, 2:3:3:2, 2:2). With metadata the frames keep their original numbers;
    with detection they are numbered from the input's first frame number. `output`, or its
    fields as keywords: how the frames are named and written.
    """
    out = replace(output, **output_fields)
    in_dir, out_dir = Path(in_dir), Path(out_dir)
    seq = discover(in_dir, out.prefix)
    _check_dirs(seq.directory, out_dir, seq.prefix, out.name(seq))
    stored = str(seq.first_meta.get("fieldOrder", "tff"))
    if field_order is None and stored not in ("tff", "bff"):
        raise UsageError(f"{seq.paths[0]}: frames are marked {stored!r}, not interlaced; give --field-order to force")
    order = check_field_order(field_order or stored)

    sources, detection = _field_sources(seq, order, pattern, tolerance, use_metadata)
    numbered_by_source = detection is None
    recovered = recovery_map(sources, order)
    if not recovered:
        raise FrameIOError(f"{seq.directory}: no complete film frame in sequence {seq.prefix}")

    cadence = detection.cadence if detection else parse_cadence(str(seq.first_meta.get("cadence", "3:2")))
    film = _recovered_film_rate(seq, cadence, film_speed)
    load = _FrameCache(seq)
    with _Staging(out_dir, seq, out, len(recovered)) as staging:
        for i, r in enumerate(recovered):
            top, bottom = load(r.top_from), load(r.bottom_from)
            rgba, aovs = _weave_layers(top, bottom)
            meta = _strip(top.meta)
            meta.update(
                inverseTelecine=cadence.name,
                topFieldFrom=seq.numbers[r.top_from],
                bottomFieldFrom=seq.numbers[r.bottom_from],
            )
            if detection is not None:
                meta["cadencePhase"] = detection.phase
            number = r.source if numbered_by_source else seq.first + r.source
            staging.write(number, rgba, meta, aovs, fps=film, timecode=timecode(i, film))
        paths = staging.publish()
    return Result(out_dir, paths, film, film, cadence, order, detection)
