"""Image probing for the validation stage: an image the scene names (texture, environment
map, planning grid) is opened and decoded completely, as the renderer will, before any task
starts; anything the renderer would fail on or render wrong is an AssetError with the
reason. Beside `meshes.py`, which does the same for mesh files."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import AssetError
from .limits import MAX_IMAGE_BYTES, open_bounded

if TYPE_CHECKING:
    import numpy as np

MAX_IMAGE_PIXELS = 16384 * 8192  # width x height of one image
# What Mitsuba's Bitmap reads; decoded here with OpenEXR, Pillow or a few lines of our own.
IMAGE_FORMATS = {".exr": "OpenEXR", ".hdr": "Radiance RGBE", ".rgbe": "Radiance RGBE", ".pfm": "PFM",
                 ".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP", ".tga": "TGA", ".ppm": "PPM", ".pgm": "PGM"}


def check_image(path: Path) -> tuple[int, int]:
    """Decode an image completely (as the renderer will) and return (width, height).

    AssetError with the reason for anything the renderer would fail on or render wrong:
    not a regular file, over MAX_IMAGE_BYTES, an unknown format, a header or pixel count
    over MAX_IMAGE_PIXELS, truncated or corrupt data, NaN or infinite pixels."""
    path = Path(path)
    kind = IMAGE_FORMATS.get(path.suffix.lower())
    if kind is None:
        raise AssetError(f"{path}: unsupported image format {path.suffix!r} (use {', '.join(sorted(IMAGE_FORMATS))})")
    fh = open_bounded(path, MAX_IMAGE_BYTES, "image file", AssetError)
    try:
        with fh:
            if kind == "OpenEXR":
                return _check_exr(path)
            if kind == "PFM":
                return _check_pfm(fh.read())
            if kind == "Radiance RGBE":
                return _check_rgbe(fh.read())
            return _check_pillow(fh)
    except AssetError as exc:
        raise AssetError(f"{path}: {exc}") from None
    except Exception as exc:  # decoders of untrusted bytes raise many kinds (struct, zlib ...)
        raise AssetError(f"{path}: not a readable {kind} image ({type(exc).__name__}: {str(exc)[:200]})") from None


def _pixels_ok(width: int, height: int) -> None:
    if width < 1 or height < 1:
        raise AssetError(f"image size {width}x{height}")
    if width * height > MAX_IMAGE_PIXELS:
        raise AssetError(f"image of {width}x{height} pixels is over the limit of {MAX_IMAGE_PIXELS} pixels")


def _finite(pixels: np.ndarray) -> None:
    import numpy as np  # only float images need it (~0.04 s of a validate without them)

    bad = ~np.isfinite(pixels)
    if bad.any():
        y, x = np.argwhere(bad.reshape(pixels.shape[0], pixels.shape[1], -1).any(axis=2))[0]
        raise AssetError(f"pixel ({int(x)}, {int(y)}) is NaN or infinite")


def _check_exr(path: Path) -> tuple[int, int]:
    import numpy as np
    import OpenEXR

    try:
        with OpenEXR.File(str(path), header_only=True) as f:
            box = f.header()["dataWindow"]
        (x0, y0), (x1, y1) = np.asarray(box[0]).tolist(), np.asarray(box[1]).tolist()
        width, height = int(x1) - int(x0) + 1, int(y1) - int(y0) + 1
        _pixels_ok(width, height)
        with OpenEXR.File(str(path)) as f:
            channels = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    except AssetError:
        raise
    except Exception as exc:  # the bindings raise RuntimeError for any bad file
        raise AssetError(f"not a readable OpenEXR image ({exc})") from None
    if not channels:
        raise AssetError("the OpenEXR image has no channels")
    for px in channels.values():
        if px.dtype.kind == "f":
            _finite(px)
    return width, height


def _check_pillow(fh: object) -> tuple[int, int]:
    from PIL import Image, UnidentifiedImageError

    Image.MAX_IMAGE_PIXELS = MAX_IMAGE_PIXELS  # Pillow refuses bigger headers itself too
    try:
        im = Image.open(fh)  # reads the header only
    except UnidentifiedImageError:
        raise AssetError("not an image Pillow recognises (corrupt, empty or another format)") from None
    except Image.DecompressionBombError as exc:
        raise AssetError(f"over the limit of {MAX_IMAGE_PIXELS} pixels ({exc})") from None
    with im:
        width, height = im.size
        _pixels_ok(width, height)
        im.load()  # decodes every pixel: truncated or corrupt data fails here
    return width, height


def _check_pfm(data: bytes) -> tuple[int, int]:
    head = data[:256].split(maxsplit=4)
    if len(head) < 4 or head[0] not in (b"PF", b"Pf"):
        raise AssetError("not a PFM image (no PF/Pf magic)")
    channels = 3 if head[0] == b"PF" else 1
    width, height, scale = int(head[1]), int(head[2]), float(head[3])
    _pixels_ok(width, height)
    if not math.isfinite(scale) or scale == 0:
        raise AssetError(f"PFM scale {scale} (must be finite and non-zero)")
    # the header is three whitespace-terminated tokens after the magic
    pos = 0
    for _ in range(4):
        while data[pos : pos + 1].isspace():
            pos += 1
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
    pos += 1
    need = width * height * channels * 4
    if len(data) - pos != need:
        raise AssetError(f"PFM data is {len(data) - pos} bytes; {width}x{height}x{channels} floats need {need}")
    import numpy as np

    _finite(np.frombuffer(data, "<f4" if scale < 0 else ">f4", width * height * channels, pos).reshape(height, width, channels))
    return width, height


def _check_rgbe(data: bytes) -> tuple[int, int]:
    """Radiance RGBE: header lines, a blank line, the resolution line, then scanlines,
    each flat (4 bytes a pixel) or adaptive run-length encoded per channel."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise AssetError("not a Radiance RGBE image (no #?RADIANCE magic)")
    blank = data.find(b"\n\n")
    if blank < 0:
        raise AssetError("the RGBE header has no end (blank line)")
    for line in data[:blank].split(b"\n"):
        if line.startswith(b"FORMAT=") and line.strip() not in (b"FORMAT=32-bit_rle_rgbe", b"FORMAT=32-bit_rle_xyze"):
            raise AssetError(f"unknown RGBE {line.decode('ascii', 'replace')!r}")
    eol = data.find(b"\n", blank + 2)
    res = data[blank + 2 : eol].split() if eol > 0 else []
    if len(res) != 4 or res[0] not in (b"-Y", b"+Y") or res[2] not in (b"+X", b"-X") or not (res[1].isdigit() and res[3].isdigit()):
        raise AssetError("the RGBE resolution line is not '-Y H +X W'")
    height, width = int(res[1]), int(res[3])
    _pixels_ok(width, height)
    pos, size = eol + 1, len(data)
    for y in range(height):
        if pos + 4 <= size and data[pos] == 2 and data[pos + 1] == 2 and (data[pos + 2] << 8 | data[pos + 3]) == width and 8 <= width < 32768:
            pos += 4
            for _channel in range(4):
                x = 0
                while x < width:
                    if pos >= size:
                        raise AssetError(f"the file is truncated at scanline {y} of {height}")
                    count = data[pos]
                    pos += 1
                    if count > 128:  # a run of one byte
                        count -= 128
                        pos += 1
                    else:  # `count` literal bytes
                        if count == 0:
                            raise AssetError(f"corrupt run length at scanline {y}")
                        pos += count
                    x += count
                    if x > width or pos > size:
                        raise AssetError(f"corrupt or truncated run at scanline {y} of {height}")
        else:  # flat (or old-style) scanline: 4 bytes a pixel
            pos += 4 * width
            if pos > size:
                raise AssetError(f"the file is truncated at scanline {y} of {height}")
    return width, height
