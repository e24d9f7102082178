"""Contact sheet: a grid of tone-mapped thumbnails with their frame numbers, as one PNG.

Thumbnails are box-filtered (each thumbnail pixel is the mean of the source pixels it
covers, `np.add.reduceat` over row and column bin edges), shown through the same view
transform as the movies, and labelled with the frame number. Long shots are sampled:
every k-th frame so that at most `max_frames` thumbnails are drawn. Matplotlib (Agg)
draws the labels and writes the PNG, to a temporary file renamed into place.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import UsageError
from .movie import ViewTransform, _publish
from .sequence import discover, read_checked

LABEL_ROWS = 18
GAP = 4


def box_resize(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Area-average downsampling of [H, W, C] to [height, width, C] (no upsampling)."""
    h, w = image.shape[:2]
    height, width = min(height, h), min(width, w)
    # Bin i covers source rows [floor(i*h/height), floor((i+1)*h/height)).
    rows = (np.arange(height) * h) // height
    cols = (np.arange(width) * w) // width
    sums = np.add.reduceat(np.add.reduceat(image.astype(np.float64), rows, axis=0), cols, axis=1)
    counts = np.diff(np.append(rows, h))[:, None, None] * np.diff(np.append(cols, w))[None, :, None]
    return (sums / counts).astype(np.float32)


def contact_sheet(
    in_dir: str | Path,
    out_path: str | Path,
    *,
    thumb_width: int = 240,
    columns: int | None = None,
    max_frames: int = 60,
    exposure: float = 0.0,
    ocio_config: str | Path | None = None,
    prefix: str | None = None,
) -> Path:
    """Write a PNG grid of the sequence in `in_dir` to `out_path` and return its path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out_path = Path(out_path)
    if out_path.suffix.lower() != ".png":
        raise UsageError(f"{out_path}: the contact sheet is written as PNG (use a .png name)")
    if thumb_width < 8 or max_frames < 1:
        raise UsageError("thumbnail width must be >= 8 and max frames >= 1")
    seq = discover(in_dir, prefix, require_even_height=False)
    step = math.ceil(len(seq) / max_frames)
    picked = list(range(0, len(seq), step))
    cols = columns or max(1, min(len(picked), math.ceil(math.sqrt(len(picked) * 16 / 9 * seq.height / seq.width))))
    rows = math.ceil(len(picked) / cols)
    tw = min(thumb_width, seq.width)
    th = max(1, round(seq.height * tw / seq.width))
    header = 30
    cell_w, cell_h = tw + GAP, th + LABEL_ROWS + GAP
    width, height = cols * cell_w + GAP, rows * cell_h + GAP + header
    sheet = np.full((height, width, 3), 0.12, np.float32)
    view = ViewTransform(exposure, ocio_config)
    places = []
    for n, index in enumerate(picked):
        r, c = divmod(n, cols)
        y, x = header + GAP + r * cell_h, GAP + c * cell_w
        thumb = box_resize(read_checked(seq, index).rgba, th, tw)
        sheet[y: y + th, x: x + tw] = view(thumb).astype(np.float32) / 65535.0
        places.append((x, y + th, seq.numbers[index]))

    dpi = 100
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    # figimage puts array row 0 at the bottom of the figure: flip so row 0 is the top.
    fig.figimage(sheet[::-1], 0, 0, origin="lower", resize=False)
    fig.text(GAP / width, 1 - 4 / height, (
        f"{seq.prefix}  frames {seq.first}-{seq.numbers[-1]}  {seq.width}x{seq.height}"
        f"{f'  {seq.fps} fps' if seq.fps else ''}\n{view.description}"
        f"{f'  (every {step}th frame)' if step > 1 else ''}"
    ), color="white", fontsize=8, va="top", ha="left", family="monospace")
    for x, y, number in places:
        fig.text(x / width, 1 - (y + 2) / height, f"{number:04d}", color="white", fontsize=9,
                 va="top", ha="left", family="monospace")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out_path.stem}.", suffix=".png", dir=out_path.parent)
    os.close(fd)
    try:
        FigureCanvasAgg(fig).print_png(tmp)
        _publish(tmp, out_path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out_path
