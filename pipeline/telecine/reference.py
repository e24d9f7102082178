"""FFmpeg's own filters (through PyAV's filter graph), as references for tests and the benchmark.

`ffmpeg_telecine`: the `telecine` filter. Half-float RGBA goes through the graph as
`rgbaf16le`, which the filter copies row by row without conversion, so its output can be
compared with ours bit for bit.

`ffmpeg_inverse_telecine`: `fieldmatch` + `decimate`, FFmpeg's inverse telecine. Both take
only planar YUV/gray integer formats, so 8-bit frames go through as the Y plane of `yuv444p`.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Iterable, Iterator

import numpy as np

from .cadence import Cadence, parse_cadence
from ..field_model import FieldOrder, check_field_order


def ffmpeg_telecine(
    frames: Iterable[np.ndarray],
    pattern: str | Cadence = "3:2",
    field_order: FieldOrder = "tff",
    rate: Fraction = Fraction(24000, 1001),
) -> Iterator[np.ndarray]:
    """Run RGBA frames ([H, W, 4], any float dtype, converted to half) through
    `telecine=first_field=..:pattern=..` and yield the output frames as float16 [H, W, 4].

    FFmpeg drops an unpaired last field (our `tail="drop"`).
    """
    import av

    cadence = parse_cadence(pattern) if isinstance(pattern, str) else pattern
    order = check_field_order(field_order)
    rate = Fraction(rate)
    graph: av.filter.Graph | None = None
    src = sink = None
    time_base = 1 / rate

    def drain() -> Iterator[np.ndarray]:
        while True:
            try:
                out = sink.pull()  # type: ignore[union-attr]
            except (av.BlockingIOError, av.EOFError):
                return
            yield out.to_ndarray()

    for i, frame in enumerate(frames):
        half = np.ascontiguousarray(frame, dtype=np.float16)
        if graph is None:
            h, w = half.shape[:2]
            graph = av.filter.Graph()
            # add_buffer has no frame_rate argument, and telecine needs one: add it by hand.
            src = graph.add(
                "buffer",
                f"video_size={w}x{h}:pix_fmt=rgbaf16le:time_base={time_base.numerator}/{time_base.denominator}"
                f":frame_rate={rate.numerator}/{rate.denominator}:pixel_aspect=1/1",
            )
            first = "top" if order == "tff" else "bottom"
            tc = graph.add("telecine", f"first_field={first}:pattern={cadence.ffmpeg_pattern}")
            sink = graph.add("buffersink")
            src.link_to(tc)
            tc.link_to(sink)
            graph.configure()
        vf = av.VideoFrame.from_ndarray(half, format="rgbaf16le")
        vf.pts = i
        vf.time_base = time_base
        src.push(vf)  # type: ignore[union-attr]
        yield from drain()
    if graph is not None:
        src.push(None)  # type: ignore[union-attr]
        yield from drain()


def ffmpeg_inverse_telecine(
    lumas: Iterable[np.ndarray],
    field_order: FieldOrder = "tff",
    rate: Fraction = Fraction(30000, 1001),
    fieldmatch: str = "",
    decimate: str = "",
) -> list[np.ndarray]:
    """FFmpeg's inverse telecine, `fieldmatch=order=..` then `decimate` (cycle 5), on 8-bit frames.

    `lumas` are [H, W] uint8 video frames; they go through the graph as `yuv444p` with the
    frame as the Y plane and neutral chroma (both filters take planar YUV, so nothing is
    converted) and the output Y planes are returned, as uint8 [H, W]. Extra filter options
    (e.g. "combmatch=full") are appended to each filter's arguments.
    """
    import av

    order = check_field_order(field_order)
    rate = Fraction(rate)
    time_base = 1 / rate
    graph = av.filter.Graph()
    src = sink = None
    out: list[np.ndarray] = []

    def drain() -> None:
        while True:
            try:
                frame = sink.pull()  # type: ignore[union-attr]
            except (av.BlockingIOError, av.EOFError):
                return
            out.append(frame.to_ndarray(format="yuv444p")[0].copy())

    for i, luma in enumerate(lumas):
        luma = np.ascontiguousarray(luma, dtype=np.uint8)
        if src is None:
            h, w = luma.shape
            src = graph.add(
                "buffer",
                f"video_size={w}x{h}:pix_fmt=yuv444p:time_base={time_base.numerator}/{time_base.denominator}"
                f":frame_rate={rate.numerator}/{rate.denominator}:pixel_aspect=1/1",
            )
            fm = graph.add("fieldmatch", f"order={order}" + (f":{fieldmatch}" if fieldmatch else ""))
            dc = graph.add("decimate", decimate)
            sink = graph.add("buffersink")
            src.link_to(fm)
            fm.link_to(dc)
            dc.link_to(sink)
            graph.configure()
        neutral = np.full_like(luma, 128)
        vf = av.VideoFrame.from_ndarray(np.stack([luma, neutral, neutral]), format="yuv444p")
        vf.pts = i
        vf.time_base = time_base
        src.push(vf)
        drain()
    if src is not None:
        src.push(None)
        drain()
    return out
