"""Bounded reading of input files: a regular file of at most a given size, refused before
a byte is read when it is a device, a pipe or a folder. Every reader of user input (scene and
preset YAML, meshes, images, baked motion) opens its files through here."""

from __future__ import annotations

import math
import os
import stat
import typing
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

if TYPE_CHECKING:  # numpy is imported by the checks that use it: `motion validate` of a scene without arrays never loads it
    import numpy as np

from .errors import InputFileError, MotionError, UsageError

ErrorFor = Callable[[str], MotionError]  # the caller's own error from "FILE: reason"

MAX_IMAGE_BYTES = 2 * 1024**3  # one texture or environment map file (images.py)
MAX_MESH_BYTES = 2 * 1024**3  # one mesh file (meshes.py)
MAX_GLTF_BYTES = 4 << 30  # one .gltf or .glb file (scene/imports/gltf.py)
MAX_GLTF_KEYS = 250_000  # animation keys of one glTF import, all channels (each becomes a keyframe record: 400,000 took 10.6 s and 0.57 GB to validate)
MAX_USD_LAYER_BYTES = 2 * 1024**3  # one USD layer file (scene/imports/usd.py)
MAX_USD_POINT_SAMPLES = 10_000  # time samples of one deforming USD mesh's points (each a mesh file and a key)
MAX_USD_POINT_VALUES = 1 << 28  # coordinates of one deforming USD mesh over all its samples (2 GB as float64)
MAX_OCIO_CONFIG_BYTES = 256 * 1024**2  # one --ocio config file, .ocio or .ocioz (telecine/movie.py)


@contextmanager
def _as(error: ErrorFor | None) -> Iterator[None]:
    """Re-raise an InputFileError as the caller's own error, `error("FILE: reason")`."""
    try:
        yield
    except InputFileError as exc:
        if error is None:
            raise
        raise error(f"{exc.file}: {exc.reason}") from None


def open_bounded(path: str | Path, limit: int, what: str, error: ErrorFor | None = None) -> typing.BinaryIO:
    """Open an input file for reading after checking that it is a regular file of at most
    `limit` bytes: a device (/dev/zero), a pipe or a folder is refused before a byte is
    read. The caller closes the file. Raises InputFileError with the reason, or
    `error("FILE: reason")` when the caller gives its own error class."""
    with _as(error):
        return _open_bounded(str(path), limit, what)


def _open_bounded(file: str, limit: int, what: str) -> typing.BinaryIO:
    try:
        # O_NONBLOCK: opening a FIFO must not wait for a writer; fstat then refuses it
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise InputFileError(file, f"{what} not found") from None
    except IsADirectoryError:
        raise InputFileError(file, f"{what} is a folder, not a file") from None
    except OSError as exc:
        raise InputFileError(file, f"cannot read {what}: {exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise InputFileError(file, f"{what} is a folder, not a file")
        if not stat.S_ISREG(st.st_mode):
            raise InputFileError(file, f"{what} is not a regular file (a device, pipe or socket)")
        if st.st_size > limit:
            raise InputFileError(file, f"{what} is {st.st_size} bytes; the limit is {limit} bytes")
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def read_bounded(path: str | Path, limit: int, what: str, error: ErrorFor | None = None) -> bytes:
    """The bytes of a regular file of at most `limit` bytes (see `open_bounded`); a file
    that grows past the limit while being read is refused too."""
    with _as(error):
        return _read_bounded(path, limit, what)


def _read_bounded(path: str | Path, limit: int, what: str) -> bytes:
    with open_bounded(path, limit, what) as fh:
        try:
            # read what fstat promised (+1 to see growth), then more only while under the
            # limit: read(n) reserves n bytes up front, so never ask for the whole limit
            data = fh.read(os.fstat(fh.fileno()).st_size + 1)
            while data and len(data) <= limit:
                more = fh.read(min(1 << 20, limit + 1 - len(data)))
                if not more:
                    break
                data += more
        except OSError as exc:
            raise InputFileError(str(path), f"cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise InputFileError(str(path), f"{what} is over the limit of {limit} bytes")
    return data


# Environment variables that size a worker's work (the README's table):
# name -> (default, most accepted or None)
ENV_SIZES: dict[str, tuple[int, int | None]] = {
    # samples one render pass traces at once (render/kernel/film.py): about 80 bytes a lane, so
    # 2^28 is ~21 GB a pass, and lane indices are 32-bit
    "MOTION_MAX_LANES": (1 << 23, 1 << 28),
    # bytes of converted assets kept on disk (render/translate/assets.py)
    "MOTION_ASSET_CACHE_CAP": (2 * 1024**3, None),
    # MB of viewed frames a run's deliverables share (telecine/movie.py ViewedFrames): 72
    # frames of 480x270 take 56 MB
    "MOTION_VIEWED_MB": (512, 1 << 20),
}


def env_size(name: str) -> int:
    """The positive integer in environment variable `name` (one of ENV_SIZES), its default
    when unset or empty; anything else, or more than its limit, is a UsageError naming
    the variable."""
    default, most = ENV_SIZES[name]
    raw = os.environ.get(name, "").strip()
    if not raw:
        return default
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if value < 1:
        raise UsageError(f"${name}: expected a positive whole number, got {raw!r}")
    if most is not None and value > most:
        raise UsageError(f"${name}: {value} is over the limit of {most}")
    return value


def check_env_sizes() -> None:
    """Every ENV_SIZES variable readable, checked before any work (a bad one would
    otherwise fail every frame in the workers)."""
    for name in ENV_SIZES:
        env_size(name)


# --- numbers the renderer can hold ------------------------------------------------------------
# One policy for every number that reaches the renderer, whatever its source (the scene file,
# an expression, an import, a bake file, a simulation): Mitsuba traces in float32, so a finite
# float64 past FLOAT32_MAX becomes inf there (the object vanishes, pixels go inf); a half-float
# EXR holds at most HALF_MAX, so a radiance above it is inf in the frame.
FLOAT32_MAX = 3.4028234663852886e38  # float(np.finfo(np.float32).max)
HALF_MAX = 65504.0


def beyond_float32(values: np.ndarray) -> np.ndarray:
    """Mask of the values a float32 cannot hold (non-finite, or finite past FLOAT32_MAX)."""
    import numpy as np

    values = np.asarray(values, dtype=np.float64)
    return ~np.isfinite(values) | (np.abs(values) > FLOAT32_MAX)


def float32_problem(value: float) -> str | None:
    """Why a single number cannot reach the renderer, or None."""
    if not math.isfinite(value):
        return f"{value} is not a finite number"
    if abs(value) > FLOAT32_MAX:
        return f"{value:g} is beyond what the renderer holds (float32: at most {FLOAT32_MAX:.3g} in magnitude)"
    return None


# The light values a camera ray meets directly, so that they are a pixel's value: an
# emitter's or a constant environment's `radiance` (a point light's intensity is not seen).
SEEN_RADIANCE = ("radiance",)


def beyond_half(values: np.ndarray) -> np.ndarray:
    """Mask of the values a half-float EXR pixel cannot hold (non-finite, or past HALF_MAX)."""
    import numpy as np

    values = np.asarray(values, dtype=np.float64)
    return ~np.isfinite(values) | (np.abs(values) > HALF_MAX)


def half_problem(value: float) -> str | None:
    """Why a radiance seen directly cannot be a pixel of a half-float frame, or None."""
    if not math.isfinite(value) or abs(value) > HALF_MAX:
        return (f"radiance {value:g} is beyond what a half-float EXR holds ({HALF_MAX:g}): "
                "its pixels would be inf; use output.pixel_type: float, or lower it")
    return None


# --- records motion wrote and reads back ------------------------------------------------------
MAX_RECORD_BYTES = 64 << 20  # one JSON record motion keeps (a cost history, an import's records, a report)
MAX_RECORD_DEPTH = 64  # nesting of a record: motion's own are a few levels deep


def _depth_within(value: object, most: int) -> bool:
    """Whether `value` nests at most `most` lists and mappings deep (walked without recursion)."""
    todo: list[tuple[object, int]] = [(value, 1)]
    while todo:
        item, depth = todo.pop()
        if isinstance(item, (dict, list)):
            if depth > most:
                return False
            todo.extend((v, depth + 1) for v in (item.values() if isinstance(item, dict) else item))
    return True


def read_json_record(path: str | Path, what: str, expect: type | tuple[type, ...] = dict, limit: int = MAX_RECORD_BYTES,
                     depth: int = MAX_RECORD_DEPTH) -> typing.Any:
    """A JSON record motion wrote earlier (a cost history, a kept import, a manifest, a run
    report), or None. Missing: None, silently. Damaged (not a regular file: a FIFO is never
    waited on; over `limit` bytes; not UTF-8 JSON; nested deeper than `depth`; not an
    `expect`): None, with one warning line naming the file, and the caller makes it again.
    Never raises for what is in the file."""
    import json
    import logging

    try:
        data = read_bounded(path, limit, what)
    except InputFileError as exc:
        if not os.path.lexists(path):
            return None
        why = exc.reason
    else:
        try:
            doc = json.loads(data)
        except (ValueError, RecursionError) as exc:  # RecursionError: nested past the decoder's stack
            why = f"not a JSON record ({type(exc).__name__})"
        else:
            if not _depth_within(doc, depth):
                why = f"nested more than {depth} deep"
            elif not isinstance(doc, expect):
                why = f"a JSON {type(doc).__name__}, not the record expected"
            else:
                return doc
    logging.getLogger("motion").warning(f"motion: warning: {path}: {what} discarded ({why}); it is made again")
    return None


# What one render worker's address space holds, measured on a worker rendering one pass
# (VmPeak, scalar_rgb, 1 spp): 1.00 GB at 2048x2048 (4.2M lanes), 1.41 GB at 2900x2900
# (8.4M lanes): about 100 bytes a lane over a base of 600 MB. A frame of more pixels than
# $MOTION_MAX_LANES renders in bands of rows (render/kernel/film.py `bands`), each within the budget.
PASS_BYTES_PER_LANE = 100
WORKER_BASE_BYTES = 600 * 1024**2
# the whole frame besides the band's pass: the film's interleaved RGBA, its readback and the
# frame written (three float32 RGBA copies)
FRAME_BYTES_PER_PIXEL = 48


def pass_lanes(width: int, height: int, spp: int) -> int:
    """Sample lanes in one render pass of a `width` x `height` frame at `spp` (render/kernel/film.py:
    a band of rows at most $MOTION_MAX_LANES pixels, or one row, and as many samples per
    pixel as the budget allows, at least one)."""
    budget = env_size("MOTION_MAX_LANES")
    pixels = max(1, min(width * height, max(width, budget)))
    return pixels * max(1, min(spp, budget // pixels))


def address_space_limit() -> int | None:
    """The address space this process (and every worker it starts) may use: the soft
    RLIMIT_AS, or None when unlimited."""
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY or soft <= 0 else soft
