"""Contact sheet: a grid of tone-mapped thumbnails with their frame numbers, as one PNG.

Thumbnails are box-filtered (each thumbnail pixel is the mean of the source pixels it
covers, `np.add.reduceat` over row and column bin edges), shown through the same view
transform as the movies, and labelled with the frame number. Long shots are sampled:
every k-th frame so that at most `max_frames` thumbnails are drawn. Gaps in the numbering
(a render of `--frames 0-100x10`) are fine: the frames that exist are shown with their own
numbers and the header says how many are missing. Matplotlib (Agg)
draws the labels and writes the PNG, to a temporary file renamed into place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import UsageError
from ..write_policy import writing
from ..timeline import format_range, rate_label
from .movie import ViewTransform
from .sequence import Sequence, discover, frame_digits, read_mapped

LABEL_ROWS = 18
GAP = 4


MAX_THUMB_WIDTH = 4096  # pixels
MAX_SHEET_FRAMES = 1000  # thumbnails on one sheet (and in one row)

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


@dataclass(frozen=True)
class SheetLayout:
    """Which frames a contact sheet shows and what its header says."""

    indices: tuple[int, ...]  # positions in the sequence, in order
    numbers: tuple[int, ...]  # their frame numbers (the labels)
    step: int  # every step-th existing frame
    missing: int  # frame numbers absent between the first and the last
    header: str  # first header line


def sheet_layout(seq: Sequence, max_frames: int = 60) -> SheetLayout:
    """Sample at most `max_frames` of the frames that exist; describe the shot in one line."""
    step = math.ceil(len(seq) / max_frames)
    picked = tuple(range(0, len(seq), step))
    span = seq.numbers[-1] - seq.first + 1
    count = f"{len(seq)} frames" if not seq.missing else f"{len(seq)} of {span} frames, {len(seq.missing)} missing"
    header = (f"{seq.prefix}  frames {format_range(seq.first, seq.numbers[-1])} ({count})  {seq.width}x{seq.height}"
              f"{f'  {rate_label(seq.fps)}' if seq.fps else ''}")  # '29.97 fps (30000/1001)', as the movies
    return SheetLayout(picked, tuple(seq.numbers[i] for i in picked), step, len(seq.missing), header)


def _text_width(text: str) -> int:
    """Pixels the sheet's header `text` takes (8-point monospace at 100 dpi), as Agg draws it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1), dpi=100)
    label = fig.text(0, 1, text, fontsize=8, va="top", ha="left", family="monospace")
    return math.ceil(label.get_window_extent(FigureCanvasAgg(fig).get_renderer()).width)


def _ordinal(n: int) -> str:
    """2 -> '2nd', 3 -> '3rd', 11 -> '11th', 21 -> '21st'."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def contact_sheet(
    in_dir: str | Path | Sequence,
    out_path: str | Path,
    *,
    thumb_width: int = 240,
    columns: int | None = None,
    max_frames: int = 60,
    view: ViewTransform | None = None,
    prefix: str | None = None,
) -> Path:
    """Write a PNG grid of the sequence in `in_dir` to `out_path` and return its path.

    Missing frame numbers are allowed (unlike telecine and movies): the sheet shows the
    frames that exist and its header counts the missing ones.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out_path = Path(out_path)
    if out_path.suffix.lower() != ".png":
        raise UsageError(f"{out_path}: the contact sheet is written as PNG (use a .png name)")
    if not 8 <= thumb_width <= MAX_THUMB_WIDTH:
        raise UsageError(f"--width {thumb_width}: a thumbnail is 8 to {MAX_THUMB_WIDTH} pixels wide")
    if not 1 <= max_frames <= MAX_SHEET_FRAMES:
        raise UsageError(f"--max-frames {max_frames}: a sheet shows 1 to {MAX_SHEET_FRAMES} frames")
    if columns is not None and not 1 <= columns <= MAX_SHEET_FRAMES:
        raise UsageError(f"--columns {columns}: expected 1 to {MAX_SHEET_FRAMES} thumbnails a row")
    view = view or ViewTransform()
    seq = in_dir if isinstance(in_dir, Sequence) else discover(in_dir, prefix, require_even_height=False,
                                                               allow_gaps=True)
    layout = sheet_layout(seq, max_frames)
    picked, step = layout.indices, layout.step
    cols = columns or max(1, min(len(picked), math.ceil(math.sqrt(len(picked) * 16 / 9 * seq.height / seq.width))))
    rows = math.ceil(len(picked) / cols)
    tw = min(thumb_width, seq.width)
    th = max(1, round(seq.height * tw / seq.width))
    header = 30
    cell_w, cell_h = tw + GAP, th + LABEL_ROWS + GAP
    title = f"{layout.header}\n{view.description}{f'  (every {_ordinal(step)} frame)' if step > 1 else ''}"
    # a sheet of a few small frames is widened to hold its header (it was cut at 160 pixels)
    width = max(cols * cell_w + GAP, 2 * GAP + _text_width(title))
    height = rows * cell_h + GAP + header
    sheet = np.full((height, width, 3), 0.12, np.float32)
    places = []
    thumbs = read_mapped(seq, lambda frame: view(box_resize(frame.rgba, th, tw)), picked)  # read side by side
    for n, (thumb, number) in enumerate(zip(thumbs, layout.numbers)):
        r, c = divmod(n, cols)
        y, x = header + GAP + r * cell_h, GAP + c * cell_w
        sheet[y: y + th, x: x + tw] = thumb.astype(np.float32) / 65535.0
        places.append((x, y + th, number))

    dpi = 100
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    # figimage puts array row 0 at the bottom of the figure: flip so row 0 is the top.
    fig.figimage(sheet[::-1], 0, 0, origin="lower", resize=False)
    fig.text(GAP / width, 1 - 4 / height, title, color="white", fontsize=8, va="top", ha="left", family="monospace")
    for x, y, number in places:
        fig.text(x / width, 1 - (y + 2) / height, frame_digits(number), color="white", fontsize=9,
                 va="top", ha="left", family="monospace")
    with writing(out_path, "writing the contact sheet", suffix=".png") as tmp:
        FigureCanvasAgg(fig).print_png(tmp)
    return out_path
