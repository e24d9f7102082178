"""A small glTF 2.0 writer (json + numpy only), for the example character
(tools/make_walker.py) and the import tests: deliberately not the library we read glTF
with (pygltflib), so a round trip checks our reader against an independent writer.

    b = GltfBuilder()
    pos = b.accessor(vertices, target="vertex")          # float32 VEC3, with min/max
    b.gltf["meshes"].append({"primitives": [{"attributes": {"POSITION": pos}}]})
    b.save("out.glb")                                    # or .gltf (buffer as a data URI)
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
COMPONENT = {np.dtype("float32"): 5126, np.dtype("uint16"): 5123, np.dtype("uint32"): 5125, np.dtype("uint8"): 5121}
TARGETS = {"vertex": 34962, "index": 34963}


class GltfBuilder:
    """Accumulates one binary buffer and the JSON that describes it."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.gltf: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": "motion tools/gltf_writer.py"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }

    def view(self, data: bytes, target: str | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            view["target"] = TARGETS[target]
        self.blob.extend(data)
        self.gltf["bufferViews"].append(view)
        return len(self.gltf["bufferViews"]) - 1

    def accessor(self, array: Any, dtype: str = "float32", target: str | None = None, bounds: bool = False, normalized: bool = False) -> int:
        """An accessor for `array` [count, width] (or [count] scalars, or [count, 4, 4] MAT4
        given row-major: written column-major as glTF wants)."""
        arr = np.asarray(array)
        if arr.ndim == 3:  # matrices: glTF stores them column-major
            arr = arr.transpose(0, 2, 1).reshape(len(arr), 16)
        if arr.ndim == 1:
            arr = arr[:, None]
        arr = np.ascontiguousarray(arr.astype(dtype))
        acc: dict[str, Any] = {
            "bufferView": self.view(arr.tobytes(), target),
            "componentType": COMPONENT[arr.dtype],
            "count": int(arr.shape[0]),
            "type": TYPES[arr.shape[1]],
        }
        if normalized:
            acc["normalized"] = True
        if bounds:
            acc["min"] = [float(x) if arr.dtype.kind == "f" else int(x) for x in arr.min(axis=0)]
            acc["max"] = [float(x) if arr.dtype.kind == "f" else int(x) for x in arr.max(axis=0)]
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1

    def node(self, **fields: Any) -> int:
        self.gltf["nodes"].append({k: v for k, v in fields.items() if v is not None})
        return len(self.gltf["nodes"]) - 1

    def image(self, png: bytes) -> int:
        """An embedded PNG image with a texture and a sampler (repeat, linear)."""
        g = self.gltf
        g.setdefault("images", []).append({"bufferView": self.view(png), "mimeType": "image/png"})
        g.setdefault("samplers", [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}])
        g.setdefault("textures", []).append({"source": len(g["images"]) - 1, "sampler": 0})
        return len(g["textures"]) - 1

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        while len(self.blob) % 4:
            self.blob.append(0)
        g = dict(self.gltf)
        g = {k: v for k, v in g.items() if v != []}
        if path.suffix.lower() == ".glb":
            g["buffers"] = [{"byteLength": len(self.blob)}]
            text = json.dumps(g, separators=(",", ":")).encode()
            text += b" " * (-len(text) % 4)
            body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(self.blob), 0x004E4942) + bytes(self.blob)
            path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        else:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
            g["buffers"] = [{"byteLength": len(self.blob), "uri": uri}]
            path.write_text(json.dumps(g, indent=1))
        return path
