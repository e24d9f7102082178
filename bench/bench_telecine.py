"""Benchmark: 3:2 pulldown of 1920x1080 half-float EXR sequences, ours vs FFmpeg's `telecine` filter.

Runs in one process, same input, same EXR reader/writer and encoder on both sides, so
the comparison isolates the pulldown itself:
  core   fields woven in memory (numpy slicing) vs the filter graph via PyAV (frames in RAM)
  exr    EXR sequence -> 60i EXR sequence (read, pulldown, write half-float ZIP)
  prores EXR sequence -> 60i ProRes 422 HQ .mov (read, pulldown, view transform, encode)
Reports fields per second (output fields: 2 per video frame) and ours / FFmpeg.

    python bench/bench_telecine.py [--frames N] [--width W --height H]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from fractions import Fraction
from pathlib import Path
from typing import Callable

import numpy as np

from motion.pipeline.frame_output import read_frame, write_frame
from motion.pipeline.telecine.cadence import parse_cadence, plan
from motion.pipeline.telecine.convert import telecine_sequence
from motion.pipeline.field_model import weave_frames
from motion.pipeline.telecine.movie import write_movie
from motion.pipeline.telecine.reference import ffmpeg_telecine
from motion.pipeline.telecine.sequence import discover

RATE = Fraction(24000, 1001)


def make_sequence(folder: Path, n: int, width: int, height: int) -> list[np.ndarray]:
    """n half-float frames: a moving gradient with mild noise (compresses like a render)."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    frames = []
    for i in range(n):
        rgba = np.empty((height, width, 4), np.float32)
        rgba[..., 0] = (x + 40 * i) / width
        rgba[..., 1] = y / height
        rgba[..., 2] = 0.5 + 0.5 * np.sin((x + y) / 50 + i)
        rgba[..., :3] += rng.normal(0, 0.01, (height, width, 3)).astype(np.float32)
        rgba[..., 3] = 1
        write_frame(folder / f"bench.{i:04d}.exr", rgba)
        frames.append(rgba.astype(np.float16).astype(np.float32))
    return frames


def timed(label: str, fields: int, fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    seconds = time.perf_counter() - start
    rate = fields / seconds
    print(f"  {label:<34} {seconds:8.3f} s  {rate:9.1f} fields/s")
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=8, help="film frames (default 8 -> 10 video frames)")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    args = parser.parse_args()

    cadence = parse_cadence("3:2")
    work = Path(tempfile.mkdtemp(prefix="bench-telecine-"))
    try:
        print(f"writing {args.frames} film frames {args.width}x{args.height} half float ...")
        film = make_sequence(work / "in", args.frames, args.width, args.height)
        video = plan(args.frames, cadence, "tff", tail="drop")  # FFmpeg drops an unpaired tail field
        fields = 2 * len(video)
        print(f"3:2 tff: {args.frames} film frames -> {len(video)} video frames ({fields} fields)\n")

        def ours_core() -> None:
            out = np.empty_like(film[0])
            for vf in video:
                weave_frames(film[vf.top], film[vf.bottom], out=out)

        def ffmpeg_core() -> None:
            for _ in ffmpeg_telecine(film, cadence, "tff", RATE):
                pass

        def ours_exr() -> None:
            telecine_sequence(work / "in", work / "ours", pattern=cadence, tail="drop", overwrite=True)

        def ffmpeg_exr() -> None:
            seq = discover(work / "in")
            frames = (read_frame(p).rgba for p in seq.paths)
            for i, out in enumerate(ffmpeg_telecine(frames, cadence, "tff", RATE)):
                write_frame(work / "ffmpeg" / f"bench.{i:04d}.exr", out, fps=RATE * cadence.rate_ratio)

        def ours_movie() -> None:
            seq = discover(work / "in")
            cache: dict[int, np.ndarray] = {}

            def load(i: int) -> np.ndarray:
                if i not in cache:
                    cache.clear() if len(cache) > 2 else None
                    cache[i] = read_frame(seq.paths[i]).rgba
                return cache[i]

            frames = (weave_frames(load(vf.top), load(vf.bottom)) for vf in video)
            write_movie(work / "ours.mov", frames, RATE * cadence.rate_ratio, width=args.width,
                        height=args.height, field_order="tff")

        def ffmpeg_movie() -> None:
            seq = discover(work / "in")
            frames = (read_frame(p).rgba for p in seq.paths)
            out = (f.astype(np.float32) for f in ffmpeg_telecine(frames, cadence, "tff", RATE))
            write_movie(work / "ffmpeg.mov", out, RATE * cadence.rate_ratio, width=args.width,
                        height=args.height, field_order="tff")

        results = {}
        for stage, ours, theirs in [("core (in memory)", ours_core, ffmpeg_core),
                                    ("EXR -> EXR", ours_exr, ffmpeg_exr),
                                    ("EXR -> ProRes 422 HQ 60i", ours_movie, ffmpeg_movie)]:
            print(stage)
            a = timed("ours (numpy)", fields, ours)
            b = timed("FFmpeg telecine filter (PyAV)", fields, theirs)
            results[stage] = (a, b)
            print(f"  ratio ours / FFmpeg: {a / b:.2f}\n")
        # The two EXR outputs must be the same pictures.
        for i in range(len(video)):
            a = read_frame(work / "ours" / f"bench.{i:04d}.exr").rgba
            b = read_frame(work / "ffmpeg" / f"bench.{i:04d}.exr").rgba
            if not np.array_equal(a, b):
                raise SystemExit(f"outputs differ at video frame {i}")
        print("EXR outputs identical (ours vs FFmpeg), frame by frame")
        print("summary: " + "; ".join(f"{k}: {a:.1f} vs {b:.1f} fields/s (x{a / b:.2f})" for k, (a, b) in results.items()))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
