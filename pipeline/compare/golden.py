"""Golden frames as a managed set: a folder of reference frames (half floats, the beauty and
the noisy layer the noise test reads) and `manifest.json` saying what they were made from.

`bless(new_dir, golden_dir)` writes the set from a render's frames; `read_manifest` reads
it back, checking every frame's bytes against the manifest's digest, so a reference that
was replaced or cut short is bad input, never a silent pass or failure.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FrameIOError, ReferenceMismatchError
from ..files import write_atomic
from ..frame_output import META_PREFIX, read_frame, write_exr
from ..scene.files import file_digest
from ..telecine.sequence import discover
from .frames import differences, frame_facts

MANIFEST = "manifest.json"
FORMAT = "motion-golden/1"
# the header attributes OpenEXR derives from the channels it is given
_STRUCTURAL = ("channels", "dataWindow", "displayWindow")
NOISY_LAYER = "noisy"  # render/denoise.py NOISY_LAYER: the undenoised beauty of a denoised frame


@dataclass(frozen=True)
class Manifest:
    """A golden set's manifest: the facts shared by its frames (scene, digest, renderer,
    resolution, settings), motion's version when blessed, and per frame its file, SHA-256,
    variant, seed and spp."""

    folder: Path
    data: dict[str, Any]

    @property
    def frames(self) -> dict[int, dict[str, Any]]:
        """Frame number -> its entry."""
        return {int(f["frame"]): f for f in self.data.get("frames", [])}

    def facts(self) -> dict[str, Any]:
        """The shared facts, in the shape `frames.differences` compares."""
        return {k: self.data.get(k) for k in ("scene_digest", "renderer", "resolution", "settings")}


def motion_version() -> str:
    """The installed motion's version."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("motion-farm")
    except PackageNotFoundError:
        return "unknown"


def bless(new_dir: str | Path, golden_dir: str | Path, prefix: str | None = None) -> Manifest:
    """Make `golden_dir` the reference set of the frames in `new_dir`: each frame rewritten
    as half floats (RGBA, and the `noisy` layer when the frame has one; its header kept),
    then `manifest.json`. Frames of an earlier set that this one lacks are removed.
    ReferenceMismatchError when the frames were not all made from one scene and settings."""
    seq = discover(new_dir, prefix, require_even_height=False, allow_gaps=True)
    golden = Path(golden_dir)
    golden.mkdir(parents=True, exist_ok=True)
    facts = [frame_facts(p) for p in seq.paths]
    first = facts[0].to_dict()
    for number, f in zip(seq.numbers, facts):
        diff = differences(f.to_dict(), first)
        if diff:
            raise ReferenceMismatchError(f"{f.path}: frame {number} was not made like frame {seq.numbers[0]} ({diff[0].replace('(reference)', f'(frame {seq.numbers[0]})')}); a golden set is one shot")
    entries = []
    scene = _scene_reference(first["scene"], Path(new_dir), golden)
    for number, path, f in zip(seq.numbers, seq.paths, facts):
        frame = read_frame(path)
        header = {k: v for k, v in frame.header.items() if k not in _STRUCTURAL}
        if scene is not None:
            header[f"{META_PREFIX}scene"] = scene  # as seen from the golden folder (no checkout path kept)
        channels: dict[str, np.ndarray] = {"RGBA": frame.rgba.astype(np.float16)}
        noisy = frame.aovs.get(NOISY_LAYER)
        if noisy is not None and noisy.ndim == 3:
            for i, comp in enumerate("RGBA"[: noisy.shape[2]]):
                channels[f"{NOISY_LAYER}.{comp}"] = noisy[..., i].astype(np.float16)
        out = golden / path.name
        write_exr(out, header, channels, doing="writing reference frame")
        entries.append({"frame": number, "file": path.name, "sha256": file_digest(out, memo=False), "variant": f.variant, "seed": f.seed, "spp": f.spp})
    old = read_manifest(golden, verify=False) if (golden / MANIFEST).is_file() else None
    data = {
        "format": FORMAT,
        "motion_version": motion_version(),
        "blessed": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "prefix": seq.prefix,
        "scene": scene,
        "scene_digest": first["scene_digest"],
        "renderer": first["renderer"],
        "resolution": first["resolution"],
        "settings": first["settings"],
        "frames": entries,
    }
    write_atomic(golden / MANIFEST, (json.dumps(data, indent=1, sort_keys=True) + "\n").encode(), "writing golden manifest")
    if old is not None:
        kept = {e["file"] for e in entries}
        for entry in old.frames.values():
            stale = golden / str(entry.get("file", ""))
            if entry.get("file") not in kept and stale.parent == golden and stale.is_file():
                stale.unlink()
    return Manifest(golden, data)


def _scene_reference(scene: str | None, frames_dir: Path, golden: Path) -> str | None:
    """The scene file named in a frame's header (relative to the frame's folder, or
    absolute), as seen from the golden folder: relative when the two share a folder below
    the root (a repository's golden frames name its scene without the checkout's path)."""
    if not scene:
        return scene
    path = Path(scene) if Path(scene).is_absolute() else (frames_dir / scene)
    path, base = path.resolve(), golden.resolve()
    try:
        common = Path(os.path.commonpath([path, base]))
    except ValueError:
        return str(path)
    return str(path) if common == Path(common.anchor) else os.path.relpath(path, base).replace(os.sep, "/")


def read_manifest(golden_dir: str | Path, *, verify: bool = True) -> Manifest | None:
    """The manifest of `golden_dir`, or None when it has none (a plain folder of frames).
    FrameIOError for a manifest that does not parse, or (with `verify`) a listed frame that
    is absent or whose bytes are not those blessed."""
    path = Path(golden_dir) / MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("frames"), list):
            raise ValueError(f"not a {FORMAT} manifest")
        manifest = Manifest(Path(golden_dir), data)
        frames = manifest.frames
    except (ValueError, TypeError, KeyError) as exc:
        raise FrameIOError(f"{path}: {exc}") from None
    if verify:
        for number, entry in frames.items():
            file = Path(golden_dir) / str(entry.get("file"))
            if not file.is_file():
                raise FrameIOError(f"{file}: reference frame {number} listed in {path.name} is not there")
            if file_digest(file, memo=False) != entry.get("sha256"):
                raise FrameIOError(f"{file}: reference frame {number} is not the one blessed (its SHA-256 differs from {path.name}'s); bless again with motion compare --bless")
    return manifest
