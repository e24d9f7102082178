"""Import budgets: a glTF's textures, buffers, images and animation keys and a USD stage's
time samples over their bounds are located errors, refused before they are read."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import pytest

from farm_util import motion


TRI = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header claims `width` x `height` (its one row of data is all there is)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(b"\x00\x00\x00\x00")) + chunk(b"IEND", b"")


def _gltf(folder: Path, edit: Any = None, keys: int = 0, texture: bytes | None = None) -> Path:
    """A one-triangle .gltf (buffer as a data URI) in `folder` with a scene importing it;
    `keys` animation keys on its node, `texture` an embedded base-colour image, then
    `edit(document)` on its JSON."""
    import sys

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parents[4] / "tools"))
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    tri = np.array(TRI, float)
    prim: dict[str, Any] = {"attributes": {"POSITION": b.accessor(tri, bounds=True), "TEXCOORD_0": b.accessor(tri[:, :2])}, "indices": b.accessor(np.array([0, 1, 2]), dtype="uint16")}
    if texture is not None:
        b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": b.image(texture)}}}]
        prim["material"] = 0
    b.gltf["meshes"].append({"name": "m", "primitives": [prim]})
    b.gltf["scenes"][0]["nodes"].append(b.node(name="tri", mesh=0))
    if keys:
        times, values = b.accessor(np.arange(keys, dtype=np.float32) / 24), b.accessor(np.zeros((keys, 3), np.float32))
        b.gltf["animations"] = [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}], "samplers": [{"input": times, "output": values}]}]
    path = b.save(folder / "a.gltf")
    if edit is not None:
        doc = json.loads(path.read_text())
        edit(doc)
        path.write_text(json.dumps(doc))
    (folder / "s.yaml").write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nimports: [{file: a.gltf}]\nlights: [{type: constant, radiance: 1}]\nrender: {resolution: [16, 16], spp: 1}\n")
    return folder / "s.yaml"


def _external(name: str, field: str) -> Any:
    """An edit that moves the glTF's buffer (field 'buffers') or adds an image file (field 'images') out to `name`."""
    def edit(doc: dict[str, Any]) -> None:
        if field == "buffers":
            doc["buffers"][0]["uri"] = name
        else:
            doc["images"] = [{"uri": name}]
            doc["textures"] = [{"source": 0}]
            doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
            doc["meshes"][0]["primitives"][0]["material"] = 0
    return edit


def _sparse(path: Path, head: bytes, size: int) -> None:
    """A file that claims `size` bytes (sparse: no real gigabytes)."""
    with open(path, "wb") as f:
        f.write(head)
        f.truncate(size)


def _validate_refused(scene: Path, *fragments: str, timeout: float = 60) -> str:
    res = motion("validate", scene, timeout=timeout)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert all(f in lines[0] for f in fragments), lines[0]
    return lines[0]


def test_a_gltf_texture_of_30000_squared_is_a_located_error(tmp_path: Path) -> None:
    (tmp_path / "e").mkdir()
    _validate_refused(_gltf(tmp_path / "e", texture=_png_header(30000, 30000)), "a.gltf: images[0]", "over the limit")  # before: DecompressionBombError traceback
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "big.png").write_bytes(_png_header(30000, 30000))
    _validate_refused(_gltf(tmp_path / "x", edit=_external("big.png", "images")), "a.gltf: images[0] 'big.png'", "over the limit")


@pytest.mark.slow  # seconds to a minute on a busy 2-core host: CI's second step (make test ARGS="-m slow")
def test_gltf_buffers_and_images_over_their_bounds_are_refused_unread(tmp_path: Path) -> None:
    huge = 5 << 30
    (tmp_path / "claim").mkdir()
    _validate_refused(_gltf(tmp_path / "claim", edit=lambda d: d["buffers"][0].__setitem__("byteLength", huge)), "buffers[0]", "byteLength 5368709120")
    (tmp_path / "buf").mkdir()
    scene = _gltf(tmp_path / "buf")
    import base64

    doc = json.loads((tmp_path / "buf" / "a.gltf").read_text())
    _sparse(tmp_path / "buf" / "huge.bin", base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1]), huge)
    doc["buffers"][0]["uri"] = "huge.bin"
    (tmp_path / "buf" / "a.gltf").write_text(json.dumps(doc))
    _validate_refused(scene, "buffers[0] 'huge.bin'", "5368709120 bytes")  # before: MemoryError
    (tmp_path / "img").mkdir()
    _sparse(tmp_path / "img" / "huge.png", _png_header(4, 4), huge)
    _validate_refused(_gltf(tmp_path / "img", edit=_external("huge.png", "images")), "images[0] 'huge.png'", "5368709120 bytes")
    (tmp_path / "fifo").mkdir()
    os.mkfifo(tmp_path / "fifo" / "pipe.bin")
    _validate_refused(_gltf(tmp_path / "fifo", edit=_external("pipe.bin", "buffers")), "buffers[0] 'pipe.bin'", "not a regular file")  # before: hung


def test_gltf_animation_keys_are_bounded(tmp_path: Path) -> None:
    from motion.pipeline.limits import MAX_GLTF_KEYS

    t0 = time.monotonic()
    _validate_refused(_gltf(tmp_path, keys=MAX_GLTF_KEYS + 1), "animations[0].samplers[0].input", f"the limit is {MAX_GLTF_KEYS}")
    assert time.monotonic() - t0 < 30  # before: every key a record (3 million: minutes and gigabytes)


def test_usd_points_with_99999_time_samples_are_refused_in_seconds(tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    samples = "\n".join(f"        {i}: [(0, 0, 0), (1, {i % 7}, 0), (0, 1, 0)]," for i in range(99_999))
    (tmp_path / "a.usda").write_text(f'#usda 1.0\n(\n    metersPerUnit = 1\n    upAxis = "Y"\n)\ndef Mesh "tri"\n{{\n    int[] faceVertexCounts = [3]\n'
                                     f"    int[] faceVertexIndices = [0, 1, 2]\n    point3f[] points.timeSamples = {{\n{samples}\n    }}\n}}\n")
    (tmp_path / "s.yaml").write_text("camera: {position: [0, 0, 4], look_at: [0, 0, 0]}\nimports: [{file: a.usda}]\nlights: [{type: constant, radiance: 1}]\nrender: {resolution: [16, 16], spp: 1}\n")
    t0 = time.monotonic()
    _validate_refused(tmp_path / "s.yaml", "a.usda: /tri.points", "99999 time samples of deforming points")  # before: hours (a cache file each, the cache listed per file)
    assert time.monotonic() - t0 < 30
