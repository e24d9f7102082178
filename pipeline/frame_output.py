"""OpenEXR frames: one write contract, atomic on disk, honest metadata; and reading back.

`write_frame(path, pixels, meta)` writes RGBA (+ optional AOV layers) to a temporary file
in the destination folder and renames it into place, so a frame on disk is either complete
or absent; never half-written, whatever kills the process.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Mapping

from .errors import DiskFaultError, FrameIOError
from .write_policy import DISK_FAULT_ERRNOS, _UMASK, _unlink_quietly, confined, disk_fault, disk_fault_errno, lost_write, publish, write_atomic, writing  # noqa: F401  (the write policy, re-exported)
from .timeline import MAX_TIMECODE_FRAMES, timecode_fields, timecode_group

PixelType = Literal["half", "float"]
Compression = Literal["zip", "zips", "piz", "zstd", "none"]

if TYPE_CHECKING:
    import numpy as np

# numpy and the OpenEXR bindings (which import numpy) are imported by the functions that
# read or write pixels or headers: a rerun that renders nothing imports neither
# (docs/reruns.md, "A rerun that renders nothing").


def _compression(name: Compression) -> Any:
    """OpenEXR's compression of a frame's `output.compression` name."""
    import OpenEXR

    return {"zip": OpenEXR.ZIP_COMPRESSION, "zips": OpenEXR.ZIPS_COMPRESSION, "piz": OpenEXR.PIZ_COMPRESSION,
            "zstd": OpenEXR.ZSTD_COMPRESSION, "none": OpenEXR.NO_COMPRESSION}[name]

# Layers holding colours (the denoiser's noisy beauty and albedo guide): channels are
# named <layer>.R/G/B/A, not .X/Y/Z/W.
COLOR_LAYERS = ("noisy", "albedo")

# Header attributes written by `write_frame` under our own prefix, so they never collide
# with standard attribute names.
META_PREFIX = "motion:"


@dataclass
class Frame:
    """A frame read back: RGBA pixels as float32 [H, W, 4], AOVs by name, the header."""

    rgba: np.ndarray
    aovs: dict[str, np.ndarray] = field(default_factory=dict)
    header: dict[str, Any] = field(default_factory=dict)

    @property
    def meta(self) -> dict[str, Any]:
        """Our own attributes, without the prefix."""
        return motion_meta(self.header)


def motion_meta(header: Mapping[str, Any]) -> dict[str, Any]:
    """Our own attributes of an EXR header (`motion:<key>`, as `write_frame` stores `meta`),
    by key without the prefix: the one reader of them (frames, telecine, stale checks)."""
    n = len(META_PREFIX)
    return {k[n:]: v for k, v in header.items() if isinstance(k, str) and k.startswith(META_PREFIX)}


def read_meta(path: str | Path) -> dict[str, Any]:
    """Our own attributes of the EXR at `path` (its header only); FrameIOError as read_header."""
    return motion_meta(read_header(path))


_EXR_MAGIC = b"\x76\x2f\x31\x01"
_PLAIN_FLAGS = 0x200  # of the version field's flags, only "single-part tiled" may be set (no long names, deep or multi-part)
MAX_PLAIN_HEADER = 64 << 20  # bytes of header read without the bindings; a larger one is left to them


def plain_meta(path: str | Path) -> dict[str, Any] | None:
    """Our own attributes (as `read_meta`) read from the header's bytes without the OpenEXR
    bindings (which import numpy): a single-part header whose `motion:` attributes are all
    `string`, `int`, `float` or `double`, values as the bindings give them. None for
    anything else (another layout, another attribute type, a header cut short or over
    MAX_PLAIN_HEADER): the caller reads the file with `read_meta`. Only for a file already
    known to read back whole (identity/record.py: WholeFrames), whose bytes the bindings
    decoded."""
    import struct

    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
            if len(head) != 8 or head[:4] != _EXR_MAGIC or head[4] != 2 or int.from_bytes(head[5:8], "little") << 8 & ~_PLAIN_FLAGS:
                return None
            meta: dict[str, Any] = {}
            read = 8
            while True:
                name = _cstring(fh)
                if name is None or read > MAX_PLAIN_HEADER:
                    return None
                if not name:
                    return meta
                kind, size_bytes = _cstring(fh), fh.read(4)
                if kind is None or len(size_bytes) != 4:
                    return None
                size = int.from_bytes(size_bytes, "little", signed=True)
                read += len(name) + len(kind) + 6 + size
                if size < 0 or read > MAX_PLAIN_HEADER:
                    return None
                value = fh.read(size)
                if len(value) != size:
                    return None
                key = name.decode("utf-8", "surrogateescape")
                if not key.startswith(META_PREFIX):
                    continue
                if kind == b"string":
                    meta[key[len(META_PREFIX):]] = value.decode("utf-8")
                elif (kind, size) in ((b"int", 4), (b"float", 4), (b"double", 8)):
                    meta[key[len(META_PREFIX):]] = struct.unpack({b"int": "<i", b"float": "<f", b"double": "<d"}[kind], value)[0]
                else:
                    return None
    except (OSError, UnicodeDecodeError):
        return None


def _cstring(fh: Any) -> bytes | None:
    """The next NUL-terminated name of an EXR header (at most 255 bytes), None if none."""
    out = bytearray()
    while len(out) <= 255:
        c = fh.read(1)
        if not c:
            return None
        if c == b"\0":
            return bytes(out)
        out += c
    return None


def _timecode_attr(tc: str, fps: Fraction | None = None) -> Any:
    """'HH:MM:SS:FF' (or ';FF' for drop-frame), FF counted at the nominal rate of `fps`
    -> OpenEXR.TimeCode, as SMPTE ST 12-1 counts rates above 30 frames/s: the frame field
    holds FF // group (`timeline.timecode_group`: 2 at 48, 50, 59.94 and 60 fps), the
    field-phase (pair) flag is set on the odd frames, and where a group is larger than a
    pair (120 fps: 4) the frame's place in it (0 .. group-1) is in the user bits, which
    ST 12-1 cannot say otherwise (docs/telecine.md, "Timecode")."""
    import OpenEXR

    drop = ";" in tc
    hh, mm, ss, ff = (int(x) for x in tc.replace(";", ":").split(":"))
    group = timecode_group(fps) if fps is not None else 1
    field, place = timecode_fields(ff, fps) if fps is not None else (ff, 0)
    if field >= MAX_TIMECODE_FRAMES:
        rate = f"at {fps} frames/s" if fps is not None else "without a frame rate (30 frames a second at most)"
        raise FrameIOError(f"timecode {tc}: frame {ff} is out of range {rate}")
    code = OpenEXR.TimeCode()
    code.hours, code.minutes, code.seconds, code.frame = hh, mm, ss, field
    code.dropFrame = drop
    if group > 1:
        code.fieldPhase = bool(place % 2)
    if group > 2:
        code.userData = place
    return code


def timecode_str(code: Any, fps: Fraction | None = None) -> str:
    """OpenEXR.TimeCode (as read back) -> 'HH:MM:SS:FF' ('HH:MM:SS;FF' for drop-frame), FF
    counted at the nominal rate of `fps` (the frame's framesPerSecond: a 60 fps frame's
    frame field 22 with the pair flag is FF 45); without `fps`, the frame field as it is."""
    sep = ";" if code.dropFrame else ":"
    group = timecode_group(fps) if fps else 1
    ff = code.frame * group + (int(code.fieldPhase) if group == 2 else code.userData % group if group > 2 else 0)
    return f"{code.hours:02d}:{code.minutes:02d}:{code.seconds:02d}{sep}{ff:02d}"


def header_timecode(header: Mapping[str, Any]) -> str | None:
    """A frame header's timecode as 'HH:MM:SS:FF' at its own rate (`timeCode` read with
    `framesPerSecond`), None without a timeCode attribute."""
    code = header.get("timeCode")
    if code is None:
        return None
    fps = header.get("framesPerSecond")
    try:
        rate = Fraction(fps) if fps is not None else None
    except (TypeError, ValueError, ZeroDivisionError):
        rate = None
    return timecode_str(code, rate if rate is not None and rate > 0 else None)


def _header_value(value: Any) -> Any:
    import numpy as np

    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, (list, tuple)) and all(isinstance(v, (int, float)) for v in value):
        return np.asarray(value, dtype=np.float32 if any(isinstance(v, float) for v in value) else np.int32)
    return value


# Mitsuba's *_rgb variants render linear Rec.709 / sRGB primaries with a D65 white:
# red, green, blue and white (x, y) as OpenEXR's standard `chromaticities` attribute.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


def write_frame(
    path: str | Path,
    rgba: np.ndarray,
    meta: Mapping[str, Any] | None = None,
    *,
    fps: Fraction | None = None,
    timecode: str | None = None,
    aovs: Mapping[str, np.ndarray] | None = None,
    pixel_type: PixelType = "half",
    compression: Compression = "zip",
    standard: Mapping[str, Any] | None = None,
) -> Path:
    """Write one frame atomically and return its path.

    rgba: [H, W, 4] (or [H, W, 3], alpha 1 is added) linear radiance.
    meta: our attributes (frame, time, shutter, spp, seed, hashes ...), stored as
          `motion:<key>`; str, int, float, Fraction and short numeric lists are allowed.
    aovs: extra layers, each [H, W] (one channel, named as given) or [H, W, C]
          (channels `<name>.X/Y/Z` or `<name>.R/G/B`... by C).
    standard: standard attributes (owner, comments, capDate ...) written as given.
    """
    import numpy as np
    import OpenEXR

    path = Path(path)
    rgba = np.asarray(rgba)
    if rgba.ndim != 3 or rgba.shape[2] not in (3, 4):
        raise FrameIOError(f"{path}: expected pixels [H, W, 3|4], got shape {rgba.shape}")
    if rgba.shape[2] == 3:
        rgba = np.concatenate([rgba, np.ones(rgba.shape[:2] + (1,), rgba.dtype)], axis=2)
    dtype = np.float16 if pixel_type == "half" else np.float32
    clamped = 0
    if pixel_type == "half":
        # a half holds at most 65504: brighter pixels (a sun's specular glint) would be inf
        # in the file; they are clamped to it and counted in the header (motion:clamped_pixels)
        over = np.abs(np.asarray(rgba, dtype=np.float64)) > 65504.0
        clamped = int(over.any(axis=2).sum())
        if clamped:
            rgba = np.clip(rgba, -65504.0, 65504.0)
            meta = {**(meta or {}), "clamped_pixels": clamped}
    channels: dict[str, np.ndarray] = {"RGBA": np.ascontiguousarray(rgba, dtype=dtype)}
    for name, layer in (aovs or {}).items():
        layer = np.asarray(layer)
        if layer.shape[:2] != rgba.shape[:2]:
            raise FrameIOError(f"{path}: AOV {name!r} has shape {layer.shape}, frame is {rgba.shape[:2]}")
        if layer.ndim == 2:
            channels[name] = np.ascontiguousarray(layer, dtype=np.float32)
        else:
            suffixes = ("RGBA" if name in COLOR_LAYERS else "XYZW") if layer.shape[2] <= 4 else [str(i) for i in range(layer.shape[2])]
            for i in range(layer.shape[2]):
                channels[f"{name}.{suffixes[i]}"] = np.ascontiguousarray(layer[..., i], dtype=np.float32)

    header: dict[str, Any] = {
        "compression": _compression(compression),
        "type": OpenEXR.scanlineimage,
        "chromaticities": REC709_CHROMATICITIES,  # (a `standard` entry may replace it)
    }
    if fps is not None:
        header["framesPerSecond"] = Fraction(fps)
    if timecode is not None:
        header["timeCode"] = _timecode_attr(timecode, Fraction(fps) if fps is not None else None)
    for key, value in (standard or {}).items():
        header[key] = _header_value(value)
    for key, value in (meta or {}).items():
        header[META_PREFIX + key] = _header_value(value)

    return write_exr(path, header, channels)


def write_exr(path: str | Path, header: Mapping[str, Any], channels: Mapping[str, np.ndarray], doing: str = "writing frame") -> Path:
    """The one EXR writer (frames, the temporal pass): `header` and `channels` as OpenEXR's
    binding takes them, written through the write policy (files.writing: a temporary file
    and an atomic rename) and read back whole before it is published. The header gets the
    digest of the pixels written (`motion:pixels_sha256`, pixel_digest), replacing any
    copied from another frame."""
    import OpenEXR

    header = {**header, META_PREFIX + PIXELS_KEY: pixel_digest(channels)}
    with writing(path, doing, verify=_reads_back) as tmp:
        OpenEXR.File(dict(header), dict(channels)).write(str(tmp))
    return Path(path)


# The header attribute (under META_PREFIX) holding the digest of a frame's pixels.
PIXELS_KEY = "pixels_sha256"


def _single_channels(channels: Mapping[str, np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """Channels as OpenEXR stores them, one plane each, by name: an [H, W, C] entry is
    split as the binding writes it ('RGBA' -> R, G, B, A; 'noisy.RGBA' -> noisy.R ...)."""
    import numpy as np

    out: list[tuple[str, np.ndarray]] = []
    for name, px in channels.items():
        px = np.asarray(px)
        if px.ndim != 3:
            out.append((name, px))
            continue
        head, _, tail = name.rpartition(".")
        names = [f"{head}.{c}" if head else c for c in tail] if len(tail) == px.shape[2] else [f"{name}.{i}" for i in range(px.shape[2])]
        out += [(n, px[..., i]) for i, n in enumerate(names)]
    return sorted(out, key=lambda item: item[0])


def pixel_digest(channels: Mapping[str, np.ndarray]) -> str:
    """SHA-256 of a frame's pixels, whatever its header says: every channel (all layers),
    in name order, each as its name, type, shape and samples. The same for the arrays
    given to the writer and for the channels read back from the file (identity/record.py
    `frame_pixels_digest`),
    so it identifies the picture: a rerun that writes the same pixels writes the same digest."""
    import numpy as np

    import hashlib

    h = hashlib.sha256()
    for name, plane in _single_channels(channels):
        h.update(f"{name}\0{plane.dtype.str}\0{plane.shape}\0".encode())
        h.update(np.ascontiguousarray(plane).data)
    return h.hexdigest()


def _reads_back(tmp: Path) -> bool:
    """Whether the temporary file decodes whole. OpenEXR does not always report a failed
    write (a full tmpfs gave a zero-byte file and no error), so a frame is published only
    once it decodes; one that does not is the disk losing our write (files.lost_write).
    An OSError reading it is raised (the write policy turns a disk's into a disk fault)."""
    import numpy as np
    import OpenEXR

    if os.stat(tmp).st_size == 0:
        return False
    try:
        with OpenEXR.File(str(tmp)) as f:
            for ch in f.channels().values():
                np.asarray(ch.pixels)
    except OSError:
        raise
    except Exception:  # the bindings raise RuntimeError for a short or corrupt file
        return False
    return True


def inside(folder: str | Path, path: str | Path) -> bool:
    """Whether `path` lies inside `folder` (lexically, after normalising `..`)."""
    base = os.path.normpath(os.path.abspath(folder))
    target = os.path.normpath(os.path.abspath(path))
    return target.startswith(base.rstrip(os.sep) + os.sep)


def read_header(path: str | Path) -> dict[str, Any]:
    """The header of an EXR, or FrameIOError if it is missing or not a readable EXR."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FrameIOError(f"{path}: no such frame")
    try:
        with OpenEXR.File(str(path), header_only=True) as f:
            return dict(f.header())
    except Exception as exc:  # the bindings raise RuntimeError for any bad file
        raise FrameIOError(f"{path}: not a readable OpenEXR file ({exc})") from None


MAX_FRAME_PIXELS = 1 << 28  # a frame we read: 16384 x 16384 (4 GiB of float32 RGBA)


def check_data_window(path: Path, header: Mapping[str, Any]) -> None:
    """A data window we can hold: FrameIOError for one that declares more than
    MAX_FRAME_PIXELS (a 100000 x 100000 header would ask for 149 GiB) or none at all."""
    try:
        lo, hi = header["dataWindow"]
        w, h = int(hi[0]) - int(lo[0]) + 1, int(hi[1]) - int(lo[1]) + 1
    except (KeyError, TypeError, ValueError, IndexError):
        raise FrameIOError(f"{path}: header has no usable dataWindow") from None
    if w < 1 or h < 1 or w * h > MAX_FRAME_PIXELS:
        raise FrameIOError(f"{path}: data window {w}x{h} is not a frame we read (at most {MAX_FRAME_PIXELS} pixels)")


def read_frame(path: str | Path) -> Frame:
    """Read a frame written by `write_frame` (or any RGB/RGBA EXR) back as float32."""
    import numpy as np
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FrameIOError(f"{path}: no such frame")
    check_data_window(path, read_header(path))  # before a pixel is allocated
    try:
        with OpenEXR.File(str(path)) as f:
            header = dict(f.header())
            chans = {name: np.array(ch.pixels) for name, ch in f.channels().items()}
    except Exception as exc:
        raise FrameIOError(f"{path}: not a readable OpenEXR file ({exc})") from None
    if "RGBA" in chans:
        rgba = chans.pop("RGBA").astype(np.float32)
    elif "RGB" in chans:
        rgb = chans.pop("RGB").astype(np.float32)
        rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)
    else:
        raise FrameIOError(f"{path}: no RGB or RGBA channels (has {sorted(chans)})")
    aovs: dict[str, np.ndarray] = {}
    grouped: dict[str, dict[str, np.ndarray]] = {}
    for name, px in chans.items():
        if "." in name:
            layer, comp = name.rsplit(".", 1)
            grouped.setdefault(layer, {})[comp] = px.astype(np.float32)
        else:
            aovs[name] = px.astype(np.float32)
    for layer, comps in grouped.items():
        aovs[layer] = np.stack([comps[k] for k in sorted(comps, key="XYZWRGBA0123456789".find)], axis=2)
    return Frame(rgba=rgba, aovs=aovs, header=header)


def is_complete(path: str | Path) -> bool:
    """True when the EXR at `path` reads back whole: its header, a data window we can hold
    and every channel decoded (not converted: nothing is kept). A truncated or foreign file
    is not. Whether it is the frame a run wants is its identity's question (identity/
    record.py `complete_as`)."""
    import numpy as np
    import OpenEXR

    try:
        check_data_window(Path(path), read_header(path))  # before a pixel is allocated
        with OpenEXR.File(str(path)) as f:
            for ch in f.channels().values():
                np.asarray(ch.pixels)
    except FrameIOError:
        return False
    except Exception:  # the bindings raise RuntimeError for a short or corrupt file
        return False
    return True
