"""EXR sequence -> PNG or JPEG images through the movies' view transform (`motion export`),
and an HTML flipbook of them (`motion view`).

The pixels go through `movie.ViewTransform` (exposure, then the sRGB curve or an OCIO
display/view), exactly as the movies and the contact sheet do, then to 8 bits per
channel: q8 = round(q16 * 255 / 65535). Pillow (already installed with matplotlib) writes
the files; each goes to a temporary name and is renamed into place (`publish`). Gaps in
the numbering are fine (each image keeps its frame number).

The flipbook is one self-contained HTML page next to its images (relative links, so the
folder can be copied or served): a scrubber, play/pause at the sequence's rate, step and
loop, keyboard (arrows, space), `#frame=N` to open at a frame, the frame number, time and
timecode, and each frame's render metadata (spp, render seconds, hashes) from its EXR
header.
"""

from __future__ import annotations

import html
import json
import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import UsageError
from ..write_policy import writing
from ..timeline import frame_timecode, rate_label
from .movie import ViewTransform
from .sequence import Sequence, discover, frame_digits, read_checked

FORMATS = {"png": ".png", "jpg": ".jpg"}
Progress = Callable[[int, int], None]

# the EXR metadata shown under each flipbook frame (when present)
INFO_KEYS = ("time", "spp", "render_seconds", "motion_blur", "seed_policy", "variant", "motion_hash", "settings_hash")


@dataclass(frozen=True)
class Exported:
    """What `export_images` wrote: the images in frame order, their frame numbers, the
    sequence they came from and the view transform's description."""

    out_dir: Path
    paths: tuple[Path, ...]
    numbers: tuple[int, ...]
    sequence: Sequence
    view: str


def to_8bit(rgb16: np.ndarray) -> np.ndarray:
    """uint16 display values -> uint8, rounded: round(v * 255 / 65535)."""
    return ((rgb16.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)


def export_images(
    in_dir: str | Path,
    out_dir: str | Path,
    fmt: str = "png",
    *,
    view: ViewTransform | None = None,
    prefix: str | None = None,
    quality: int = 92,
    progress: Progress | None = None,
) -> Exported:
    """Write every frame of the sequence in `in_dir` as `<prefix>.<frame>.png|jpg` in
    `out_dir` (created). JPEG `quality` 1-95."""
    if fmt not in FORMATS:
        raise UsageError(f"--format: {fmt!r} is not one of {', '.join(FORMATS)}")
    if not 1 <= int(quality) <= 95:
        raise UsageError(f"--quality must be 1-95, got {quality}")
    view = view or ViewTransform()
    seq = discover(in_dir, prefix, require_even_height=False, allow_gaps=True)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    from PIL import Image, PngImagePlugin

    paths = []
    for i, number in enumerate(seq.numbers):
        rgb = to_8bit(view(read_checked(seq, i).rgba))
        path = out / f"{seq.prefix}.{frame_digits(number, seq.padding)}{FORMATS[fmt]}"
        with writing(path, f"writing the {fmt.upper()} image", suffix=FORMATS[fmt]) as tmp:
            image = Image.fromarray(rgb, "RGB")
            if fmt == "png":
                info = PngImagePlugin.PngInfo()
                info.add_text("Source", seq.paths[i].name)
                info.add_text("Description", view.description)
                image.save(tmp, format="PNG", pnginfo=info)
            else:
                image.save(tmp, format="JPEG", quality=int(quality), subsampling=0)
        paths.append(path)
        if progress is not None:
            progress(i + 1, len(seq))
    return Exported(out, tuple(paths), seq.numbers, seq, view.description)


def _frame_info(seq: Sequence, index: int, number: int, fps: Fraction | None) -> dict[str, Any]:
    from ..frame_output import header_timecode, motion_meta, read_header

    header = read_header(seq.paths[index])
    meta = motion_meta(header)
    info: dict[str, Any] = {"frame": number, "file": seq.paths[index].name}
    # the frame's own timecode (it follows the frame number, and a pulldown's continues the
    # film's: docs/telecine.md); a header without one: the frame number at the nominal rate
    if header.get("timeCode") is not None:
        info["timecode"] = header_timecode(header)
    elif fps:
        info["timecode"] = (frame_timecode(number, fps) or "") if round(fps) == fps or fps.denominator == 1001 else ""
    for key in INFO_KEYS:
        value = meta.get(key)
        if isinstance(value, (int, float, str)) and not isinstance(value, bool):
            info[key] = round(value, 4) if isinstance(value, float) else value
    return info


def write_flipbook(exported: Exported, path: str | Path, title: str | None = None) -> Path:
    """Write the HTML flipbook of `exported` images to `path` (in or above their folder:
    the page links them relatively) and return its path."""
    path = Path(path)
    seq = exported.sequence
    try:
        rel = [os.path.relpath(p, path.parent).replace(os.sep, "/") for p in exported.paths]
    except ValueError:
        raise UsageError(f"{path}: the flipbook must be on the same drive as its images") from None
    fps = seq.fps
    frames = [dict(_frame_info(seq, i, n, fps), src=src) for i, (n, src) in enumerate(zip(exported.numbers, rel))]
    data = {
        "title": title or seq.prefix,
        "fps": float(fps) if fps else 24.0,
        "fps_text": rate_label(fps) if fps else "24 fps (assumed)",
        "width": seq.width,
        "height": seq.height,
        "view": exported.view,
        "missing": len(seq.missing),  # a count: frames 0 and 2**31 are two frames, not a list of 2**31
        "frames": frames,
    }
    page = _PAGE.replace("__TITLE__", html.escape(data["title"])).replace(
        "__DATA__", json.dumps(data).replace("</", "<\\/"))
    with writing(path, "writing the flipbook", suffix=".html") as tmp:
        tmp.write_text(page, encoding="utf-8")
    return path


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>__TITLE__ - motion flipbook</title>
<style>
  body { background: #1e1e1e; color: #ddd; font: 13px/1.4 monospace; margin: 16px; }
  #stage { display: block; max-width: 100%; image-rendering: auto; background: #000; }
  #controls { display: flex; gap: 8px; align-items: center; margin: 8px 0; }
  #scrubber { flex: 1; }
  button { font: inherit; }
  #info td { padding: 0 12px 0 0; }
</style>
</head>
<body>
<h1 id="title" style="font-size: 15px"></h1>
<img id="stage" alt="frame">
<div id="controls">
  <button id="prev" title="previous frame (left arrow)">&lt;</button>
  <button id="play" title="play / pause (space)">play</button>
  <button id="next" title="next frame (right arrow)">&gt;</button>
  <input id="scrubber" type="range" min="0" value="0" step="1">
  <label><input id="loop" type="checkbox" checked> loop</label>
  <span id="counter"></span>
</div>
<table id="info"></table>
<p id="about"></p>
<script id="flipbook-data" type="application/json">__DATA__</script>
<script>
"use strict";
const data = JSON.parse(document.getElementById("flipbook-data").textContent);
const stage = document.getElementById("stage");
const scrubber = document.getElementById("scrubber");
const playButton = document.getElementById("play");
let loaded = 0, broken = 0;
const images = data.frames.map(f => {
  const im = new Image();
  im.onload = () => { loaded += 1; document.body.dataset.loaded = String(loaded); };
  im.onerror = () => { broken += 1; document.body.dataset.broken = String(broken); };
  im.src = f.src;
  return im;
});
let index = 0, timer = null;
scrubber.max = String(data.frames.length - 1);
// small renders are shown at least 640 pixels wide (pixelated, so their pixels stay visible)
stage.style.width = Math.max(data.width, 640) + "px";
if (data.width < 320) stage.style.imageRendering = "pixelated";
document.getElementById("title").textContent = data.title;
document.getElementById("about").textContent =
  `${data.frames.length} frames, ${data.width}x${data.height}, ${data.fps_text}; ${data.view}` +
  (data.missing ? `; ${data.missing} frame numbers missing` : "");
function show(i) {
  index = Math.max(0, Math.min(data.frames.length - 1, i));
  const f = data.frames[index];
  stage.src = f.src;
  scrubber.value = String(index);
  document.getElementById("counter").textContent = `${index + 1} / ${data.frames.length}`;
  const rows = Object.entries(f).filter(([k]) => k !== "src");
  document.getElementById("info").innerHTML = "";
  for (const [k, v] of rows) {
    const tr = document.createElement("tr");
    const a = document.createElement("td"); a.textContent = k;
    const b = document.createElement("td"); b.textContent = String(v);
    b.id = "info-" + k;
    tr.append(a, b);
    document.getElementById("info").append(tr);
  }
  document.body.dataset.frame = String(f.frame);
}
function step(d) {
  let i = index + d;
  if (i >= data.frames.length || i < 0) {
    if (!document.getElementById("loop").checked) { pause(); return; }
    i = (i + data.frames.length) % data.frames.length;
  }
  show(i);
}
function play() { if (timer === null) { timer = setInterval(() => step(1), 1000 / data.fps); playButton.textContent = "pause"; } }
function pause() { if (timer !== null) { clearInterval(timer); timer = null; } playButton.textContent = "play"; }
playButton.onclick = () => (timer === null ? play() : pause());
document.getElementById("prev").onclick = () => { pause(); step(-1); };
document.getElementById("next").onclick = () => { pause(); step(1); };
scrubber.oninput = () => { pause(); show(Number(scrubber.value)); };
document.addEventListener("keydown", e => {
  if (e.key === "ArrowLeft") { pause(); step(-1); }
  else if (e.key === "ArrowRight") { pause(); step(1); }
  else if (e.key === " ") { e.preventDefault(); timer === null ? play() : pause(); }
});
// #frame=N opens at frame number N (a link to one frame)
function fromHash() {
  const m = /frame=(-?\\d+)/.exec(location.hash);
  const i = m ? data.frames.findIndex(f => f.frame === Number(m[1])) : -1;
  show(i >= 0 ? i : 0);
}
window.addEventListener("hashchange", fromHash);
fromHash();
</script>
</body>
</html>
"""
