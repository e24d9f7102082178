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
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .. import VERSION
from ..errors import FrameIOError, ReferenceMismatchError, UsageError
from ..write_policy import write_atomic
from ..frame_output import META_PREFIX, read_frame, write_exr
from ..scene.files import file_digest
from .frames import find_frames, frame_facts, incomparable, notes, read_pixels

MANIFEST = "manifest.json"
FORMAT = "motion-golden/1"
# the header attributes OpenEXR derives from the channels it is given
_STRUCTURAL = ("channels", "dataWindow", "displayWindow")
NOISY_LAYER = "noisy"  # render/output/denoise.py NOISY_LAYER: the undenoised beauty of a denoised frame
MAX_MANIFEST_BYTES = 64 << 20  # about 150 bytes a frame: far above any shot's manifest
_FRAME_NUMBER = Annotated[int, Field(ge=-(2**63), lt=2**63)]
_FILE_NAME = re.compile(r"^[^/\\\x00]+\.exr$", re.IGNORECASE)


class _Entry(BaseModel):
    """One frame of a manifest, as read back (types checked, strictly: no 1.0 for 1)."""

    model_config = ConfigDict(strict=True, extra="allow")
    frame: _FRAME_NUMBER
    file: Annotated[str, Field(min_length=1, max_length=255)]
    sha256: Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]
    variant: str | None = None
    seed: int | None = None
    spp: int | None = None
    motion_hash: str | None = None

    @field_validator("file")
    @classmethod
    def _plain_name(cls, value: str) -> str:
        if value.startswith(".") or not _FILE_NAME.match(value):
            raise ValueError(f"{value!r} is not a frame file of the set (a plain name.NNNN.exr inside its folder)")
        return value


class _ManifestModel(BaseModel):
    """A manifest as read back: its format, the shared facts and the frames."""

    model_config = ConfigDict(strict=True, extra="allow")
    format: Literal["motion-golden/1"]
    frames: Annotated[list[_Entry], Field(min_length=1, max_length=1_000_000)]
    prefix: str | None = None
    scene: str | None = None
    scene_digest: str | None = None
    renderer: str | None = None
    resolution: tuple[int, int] | None = None
    settings: dict[str, Any] | None = None
    look_parts: dict[str, str] | None = None


@dataclass(frozen=True)
class Manifest:
    """A golden set's manifest: the facts shared by its frames (scene, digest, renderer,
    resolution, settings, look parts), motion's version when blessed, and per frame its
    file, SHA-256, variant, seed, spp and motion digest."""

    folder: Path
    data: dict[str, Any]

    @property
    def frames(self) -> dict[int, dict[str, Any]]:
        """Frame number -> its entry."""
        return {int(f["frame"]): f for f in self.data.get("frames", [])}

    def paths(self) -> dict[int, Path]:
        """Frame number -> its reference file: only what the manifest lists."""
        return {n: self.folder / str(e["file"]) for n, e in self.frames.items()}

    def facts(self) -> dict[str, Any]:
        """The shared facts, in the shape `frames.notes` compares."""
        return {k: self.data.get(k) for k in ("scene_digest", "renderer", "resolution", "settings", "look_parts")}


def bless(new_dir: str | Path, golden_dir: str | Path, prefix: str | None = None, frames: list[int] | None = None) -> Manifest:
    """Make `golden_dir` the reference set of the frames in `new_dir` (`frames`: only
    these): each frame rewritten as half floats (RGBA, and the `noisy` layer when the frame
    has one; its header kept), then `manifest.json`. Frames of an earlier set that this one
    lacks are removed. Refused before anything is written: blessing into `new_dir` itself,
    frames not made alike (ReferenceMismatchError), frames with a NaN or infinite pixel."""
    new, golden = Path(new_dir), Path(golden_dir)
    if golden.exists() and not golden.is_dir():
        raise UsageError(f"{golden}: the golden set must be a folder, and this is a file")
    if golden.is_dir() and new.is_dir() and os.path.samefile(golden, new):
        raise UsageError(f"{golden}: cannot bless frames into their own folder (it would rewrite the render's frames as references); name another folder")
    name, found = find_frames(new, prefix)
    if frames is not None:
        absent = [n for n in frames if n not in found]
        if absent:
            raise FrameIOError(f"{new}: no frame {absent[0]} of sequence {name} to bless" + (f" ({len(absent)} frames absent)" if len(absent) > 1 else ""))
        found = {n: found[n] for n in sorted(set(frames))}
    numbers = sorted(found)
    facts = {n: frame_facts(found[n]) for n in numbers}
    first = facts[numbers[0]].to_dict()
    for number in numbers:
        this = facts[number].to_dict()
        diff = incomparable(this, first) + [d for d in notes(this, first) if d != "the frame's motion differs"]
        if diff:
            raise ReferenceMismatchError(f"{found[number]}: frame {number} was not made like frame {numbers[0]} ({diff[0].replace('(reference)', f'(frame {numbers[0]})')}); a golden set is one shot")
    for number in numbers:
        _check_finite(found[number], number)
    golden.mkdir(parents=True, exist_ok=True)
    scene = _scene_reference(first["scene"], new, golden)
    entries = [_bless_frame(found[n], n, facts[n].to_dict(), golden, scene) for n in numbers]
    try:
        old = read_manifest(golden, verify=False)
    except FrameIOError:
        old = None  # a damaged manifest names nothing to remove
    data = {
        "format": FORMAT,
        "motion_version": VERSION,
        "blessed": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "prefix": name,
        "scene": scene,
        "scene_digest": first["scene_digest"],
        "renderer": first["renderer"],
        "resolution": first["resolution"],
        "settings": first["settings"],
        "look_parts": first["look_parts"],
        "frames": entries,
    }
    write_atomic(golden / MANIFEST, (json.dumps(data, indent=1, sort_keys=True, allow_nan=False) + "\n").encode(), "writing golden manifest")
    if old is not None:
        kept = {e["file"] for e in entries}
        for stale in old.paths().values():
            if stale.name not in kept and stale.is_file() and not stale.is_symlink():
                stale.unlink()
    return Manifest(golden, data)


def _check_finite(path: Path, number: int) -> None:
    """FrameIOError when frame `number` holds a NaN or infinite pixel: never a reference."""
    _, rgba, noisy = read_pixels(path, NOISY_LAYER)
    for what, pixels in (("beauty", rgba), (NOISY_LAYER, noisy)):
        if pixels is not None and not np.isfinite(pixels).all():
            count = int((~np.isfinite(pixels)).any(axis=-1).sum())
            raise FrameIOError(f"{path}: frame {number} has {count} pixel(s) that are NaN or infinite in its {what}; such a frame is no reference")


def _bless_frame(path: Path, number: int, facts: Mapping[str, Any], golden: Path, scene: str | None) -> dict[str, Any]:
    """Write one reference frame into `golden`; its manifest entry."""
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
    return {"frame": number, "file": path.name, "sha256": file_digest(out, memo=False), "variant": facts["variant"], "seed": facts["seed"],
            "spp": facts["spp"], "motion_hash": facts["motion_hash"]}


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
    FrameIOError, located, for a manifest that is not a regular file of bounded size, does
    not parse, or holds a wrong type anywhere (`frames[3].frame: ...`), a file that is not a
    plain name inside the set, a frame listed twice; and (with `verify`) a listed frame that
    is absent or whose bytes are not those blessed."""
    golden = Path(golden_dir)
    path = golden / MANIFEST
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise FrameIOError(f"{path}: cannot read the golden manifest ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise FrameIOError(f"{path}: the golden manifest is not a regular file")
    if st.st_size > MAX_MANIFEST_BYTES:
        raise FrameIOError(f"{path}: {st.st_size} bytes, more than a golden manifest holds ({MAX_MANIFEST_BYTES}); not a manifest")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FrameIOError(f"{path}: cannot read the golden manifest ({exc.strerror or exc})") from None
    try:
        model = _ManifestModel.model_validate_json(raw)
    except ValidationError as exc:
        raise FrameIOError(f"{path}: not a {FORMAT} manifest: {_first_problem(exc)}") from None
    data = model.model_dump(mode="json")
    manifest = Manifest(golden, data)
    _check_entries(path, data["frames"])
    if verify:
        for number, file in manifest.paths().items():
            if not file.is_file():
                raise FrameIOError(f"{file}: reference frame {number} listed in {path.name} is not there")
            if file.is_symlink() or file.resolve().parent != golden.resolve():
                raise FrameIOError(f"{file}: reference frame {number} listed in {path.name} leads outside the set; a reference is a file of the set itself")
            if file_digest(file, memo=False) != manifest.frames[number]["sha256"]:
                raise FrameIOError(f"{file}: reference frame {number} is not the one blessed (its SHA-256 differs from {path.name}'s); bless again with motion compare --bless")
    return manifest


def _check_entries(path: Path, entries: list[dict[str, Any]]) -> None:
    """Each frame number and file listed once."""
    numbers: set[int] = set()
    files: set[str] = set()
    for i, entry in enumerate(entries):
        if entry["frame"] in numbers:
            raise FrameIOError(f"{path}: frames[{i}].frame: frame {entry['frame']} is listed twice")
        if entry["file"] in files:
            raise FrameIOError(f"{path}: frames[{i}].file: {entry['file']!r} is listed twice")
        numbers.add(entry["frame"])
        files.add(entry["file"])


def _first_problem(exc: ValidationError) -> str:
    """The first of pydantic's problems as `where: what (got ...)`, and how many more."""
    errors = exc.errors(include_url=False)
    first = errors[0]
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in first["loc"]).lstrip(".") or "the document"
    got = first.get("input")
    shown = ""
    if first["type"] not in ("missing", "json_invalid") and not isinstance(got, (dict, list)):
        text = repr(got)
        shown = f" (got {text[:60]}{'...' if len(text) > 60 else ''})"
    more = f"; and {len(errors) - 1} more problem(s)" if len(errors) > 1 else ""
    return f"{where}: {first['msg']}{shown}{more}"
