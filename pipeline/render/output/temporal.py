"""Temporal stability of denoised frames: `render.temporal: reproject` (docs/denoise.md).

Per-frame denoising of independent noise leaves a low-frequency residual that changes from
frame to frame: the image "swims". Here each frame's noisy beauty is blended with its
neighbours' (frames n-2 .. n+2 of the timeline, RADIUS), reprojected by the motion vectors and
kept only where they agree with frame n, and the blend is denoised with frame n's guides.
Consecutive blends share four fifths of their samples, so their denoised results differ
far less; where a neighbour does not agree (disocclusion, a wrong motion estimate, a
changing light) frame n keeps its own pixels only, so nothing ghosts.

Why a pass after the frames and not in the worker: a frame's result must not depend on
which worker or shard rendered its neighbours. The pass reads the neighbours' noisy, guide
and motion layers from the output folder (they are bit-identical whoever rendered them)
and runs only for a frame whose timeline neighbours are all complete there; any other
frame keeps its per-frame denoised image and `motion:temporal = pending` until a later run
(the gather run after shards, or `--resume`) finds its neighbours. So the temporal result
of a frame is one function of the same bits, whatever the worker, shard or run count.

Reprojection: the motion AOV is the first hit's screen motion from shutter open to close;
over a whole frame interval the motion is that divided by the shutter fraction s (a
constant-velocity extrapolation; with s = 0 there is no motion estimate and only what
does not move on screen agrees). A neighbour d frames away is sampled (bilinearly) at
p + d * motion(p) / s.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ...timeline import format_frames
from ..kernel.aovs import BY_NAME, layer
from .denoise import NOISY_LAYER, denoise_frame

# the layers the pass reads (the AOV table's names for them)
ALBEDO, NORMAL, MOTION = layer("albedo"), layer("normal"), layer("motion")

RADIUS = 2  # neighbours on each side (bench_denoise: radius 2 flickers 0.4x per-frame denoising, radius 1 0.52x)
# agreement thresholds: guides (albedo in [0, 1], normal components in [-1, 1]) and the
# colour test in standard errors of the 3x3 local means
ALBEDO_TOL = 0.05
NORMAL_TOL = 0.1
MOTION_TOL = 0.5  # pixels: the neighbour's own motion vector must match (moving edges)
COLOUR_SIGMAS = 3.0


def warp(image: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Backward warp: out(p) = image(p + flow(p)) by bilinear interpolation; flow [H, W, 2]
    in pixels (+x right, +y down). Returns the warped image and where it was inside."""
    h, w = image.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    x = xs + flow[..., 0]
    y = ys + flow[..., 1]
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    x = np.clip(x, 0, w - 1)
    y = np.clip(y, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2 if w > 1 else 0)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2 if h > 1 else 0)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    img = image if image.ndim == 3 else image[..., None]
    out = (img[y0, x0] * (1 - fx) + img[y0, x1] * fx) * (1 - fy) + (img[y1, x0] * (1 - fx) + img[y1, x1] * fx) * fy
    out = out.astype(np.float32)
    return (out if image.ndim == 3 else out[..., 0]), inside


def _box3(image: np.ndarray) -> np.ndarray:
    """3x3 mean (edges replicated)."""
    p = np.pad(image, ((1, 1), (1, 1)) + ((0, 0),) * (image.ndim - 2), mode="edge")
    h, w = image.shape[:2]
    return sum(p[dy : dy + h, dx : dx + w] for dy in range(3) for dx in range(3)) / 9.0


def agreement(cur: dict[str, np.ndarray], other: dict[str, np.ndarray], inside: np.ndarray) -> np.ndarray:
    """Where a reprojected neighbour shows the same thing as the current frame: same
    albedo and normal guides, the same motion vector (a pixel that a moving edge covers only
    in part has an averaged, wrong one: the neighbour's pixel there differs), and 3x3 colour
    means within COLOUR_SIGMAS standard errors."""
    ok = inside.copy()
    if MOTION in other:
        ok &= np.abs(other[MOTION] - cur[MOTION]).max(axis=2) < MOTION_TOL
    ok &= np.abs(other[ALBEDO] - cur[ALBEDO]).max(axis=2) < ALBEDO_TOL
    ok &= np.abs(other[NORMAL] - cur[NORMAL]).max(axis=2) < NORMAL_TOL
    c0, c1 = cur["color"], other["color"]
    m0, m1 = _box3(c0), _box3(c1)
    var = np.maximum(_box3(c0 * c0) - m0 * m0, 0) + np.maximum(_box3(c1 * c1) - m1 * m1, 0)
    tol = COLOUR_SIGMAS * np.sqrt(var / 9.0) + 0.02 * (np.abs(m0) + np.abs(m1)) / 2 + 1e-4
    ok &= (np.abs(m1 - m0) <= tol).all(axis=2)
    return ok


def blend(cur: dict[str, np.ndarray], neighbours: Sequence[tuple[int, dict[str, np.ndarray]]], shutter_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """The current frame's noisy colour averaged with each neighbour's (d frames away),
    reprojected and kept where it agrees. Returns the blend and the per-pixel count of
    frames in it (1 = the current frame alone)."""
    flow = cur[MOTION] / shutter_fraction if shutter_fraction > 0 else np.zeros_like(cur[MOTION])
    total = cur["color"].astype(np.float64)
    count = np.ones(total.shape[:2])
    for d, other in neighbours:
        f = d * flow
        warped = {}
        inside = np.ones(total.shape[:2], bool)
        for key in ("color", ALBEDO, NORMAL, MOTION):
            if key not in other:
                continue
            warped[key], inside_k = warp(other[key], f)
            inside &= inside_k
        ok = agreement(cur, warped, inside)
        total += np.where(ok[..., None], warped["color"], 0.0)
        count += ok
    return (total / count[..., None]).astype(np.float32), count


# --- the pass over an output folder ---------------------------------------------------------


def _read(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        channels = {name: np.array(ch.pixels) for name, ch in f.channels().items()}
    return header, channels


def _layers(channels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The pass's inputs from a frame's channels. A layer the frame lacks (the scalar
    fallback renders no AOVs) reads as zeros: no motion, and guides that always agree, so
    only the colour test decides there."""
    shape = channels[f"{NOISY_LAYER}.R"].shape

    def stack(name: str, comps: Sequence[str]) -> np.ndarray:
        return np.stack([channels.get(f"{name}.{c}", np.zeros(shape)).astype(np.float32) for c in comps], axis=2)

    layers = {"color": stack(NOISY_LAYER, "RGB"), "alpha": channels[f"{NOISY_LAYER}.A"].astype(np.float32)}
    for aov in (BY_NAME["albedo"], BY_NAME["normal"], BY_NAME["motion"]):
        layers[aov.layer] = stack(aov.layer, aov.suffixes)
    return layers


def _meta(header: dict[str, Any], key: str) -> Any:
    from ...frame_output import META_PREFIX

    return header.get(META_PREFIX + key)


def process_frame(path: str, neighbours: list[tuple[int, str]]) -> dict[str, Any]:
    """Blend, denoise and rewrite one frame (RGBA only; every layer and attribute kept).
    `neighbours`: (frame offset, path) of its complete timeline neighbours."""
    from ...frame_output import META_PREFIX, write_exr

    header, channels = _read(Path(path))
    cur = _layers(channels)
    fps = header.get("framesPerSecond")
    s = (float(_meta(header, "shutter_close")) - float(_meta(header, "shutter_open"))) * float(fps) if fps else 0.0
    others = []
    hashes = []
    for d, p in neighbours:
        h, ch = _read(Path(p))
        others.append((d, _layers(ch)))
        hashes.append(f"{_meta(h, 'frame')}:{_meta(h, 'motion_hash')}")
    color, count = blend(cur, others, s)
    rgba = np.concatenate([cur["color"], cur["alpha"][..., None]], axis=2)
    aovs = {ALBEDO: cur[ALBEDO], NORMAL: cur[NORMAL]}
    out, _, meta = denoise_frame(rgba, aovs, color=color)
    for c, name in enumerate("RGB"):  # alpha (coverage) stays as it is
        channels[name] = np.ascontiguousarray(out[..., c], dtype=channels[name].dtype)
    header[META_PREFIX + "temporal"] = "reproject"
    header[META_PREFIX + "temporal_neighbours"] = ",".join(hashes)
    header[META_PREFIX + "temporal_blended"] = float((count > 1).mean())  # share of pixels with a neighbour
    header[META_PREFIX + "denoise_seconds"] = meta["denoise_seconds"]
    for key in ("channels", "dataWindow", "displayWindow"):
        header.pop(key, None)
    write_exr(path, header, channels)
    return {"frame": int(_meta(header, "frame")), "blended": float((count > 1).mean())}


def _neighbour_state(path: Path, look: str) -> str | None:
    """`motion_hash` of a complete frame of this look (its key's half that is not motion:
    identity/look.py; a frame kept from a run of an edit that did not change it counts),
    None if absent or other."""
    from ...errors import FrameIOError
    from ...frame_output import META_PREFIX, read_header

    try:
        header = read_header(path)
    except FrameIOError:
        return None
    if header.get(META_PREFIX + "look_hash") != look or f"{META_PREFIX}temporal" not in header:
        return None
    return f"{header.get(META_PREFIX + 'frame')}:{header.get(META_PREFIX + 'motion_hash')}"


def temporal_pass(loaded: Any, job: Any, frame_path: Callable[[int], Path], frames: Sequence[int], workers: int = 1, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the temporal mode over `frames`, each where `frame_path` says the job wrote it
    (the worker's `job.frame_path`; see the module docstring): frames
    whose neighbours are all complete get the blend; the others stay `pending`. A frame
    already done with the same neighbours is left alone. Returns a summary."""
    from ...frame_output import META_PREFIX, read_header

    first, last = loaded.scene.timeline.first, loaded.scene.timeline.last
    todo: list[tuple[str, list[tuple[int, str]]]] = []
    pending: list[int] = []
    for f in frames:
        path = frame_path(f)
        me = _neighbour_state(path, job.look)
        if me is None:
            continue  # not rendered (failed, interrupted): nothing to do
        near = [(d, frame_path(f + d)) for d in range(-RADIUS, RADIUS + 1) if d and first <= f + d <= last]
        states = [_neighbour_state(p, job.look) for _, p in near]
        if any(s is None for s in states):
            pending.append(f)
            continue
        header = read_header(path)
        if header.get(META_PREFIX + "temporal") == "reproject" and header.get(META_PREFIX + "temporal_neighbours") == ",".join(states):  # type: ignore[arg-type]
            continue
        todo.append((str(path), [(d, str(p)) for d, p in near]))
    done: list[dict[str, Any]] = []
    if todo:
        log(f"  temporal: blending {len(todo)} frames with their reprojected neighbours")
        if workers > 1 and len(todo) > 1:
            with ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=get_context("spawn")) as pool:
                done = list(pool.map(process_frame, *zip(*todo)))
        else:
            done = [process_frame(p, n) for p, n in todo]
    if pending:
        log(f"  temporal: frames {format_frames(pending)} keep their per-frame denoising until their neighbours are rendered")
    return {"mode": "reproject", "blended": [d["frame"] for d in done], "pending": pending, "blended_share": {d["frame"]: d["blended"] for d in done}}
