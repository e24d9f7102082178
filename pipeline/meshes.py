"""Triangle meshes from .obj and .ply (ascii and binary) files, read with numpy: for mesh
colliders and bodies (dynamics) and for bind and key meshes (deformation). Vertices stay
in file order; polygons are fan-triangulated. Returns vertices [v, 3] and triangle
indices [t, 3]. (The renderer reads meshes through Mitsuba and its asset cache.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import AssetError

_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4", "float": "f4", "double": "f8",
              "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2", "int32": "i4", "uint32": "u4", "float32": "f4", "float64": "f8"}


def load_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of an .obj or .ply file; AssetError if unreadable."""
    try:
        if path.suffix.lower() == ".obj":
            return _load_obj(path)
        return _load_ply(path)
    except AssetError:
        raise
    except (OSError, ValueError, IndexError, KeyError) as exc:
        raise AssetError(f"{path}: cannot read mesh: {exc}") from None


def _fan(polygons: list[list[int]]) -> np.ndarray:
    tris = [(p[0], p[i], p[i + 1]) for p in polygons for i in range(1, len(p) - 1)]
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def _load_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(c) for c in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) for p in parts[1:]]
            faces.append([i - 1 if i > 0 else len(verts) + i for i in idx])
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), _fan(faces)


def _load_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise AssetError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    body_start = data.index(b"\n", end) + 1
    fmt = "ascii"
    elements: list[tuple[str, int, list[tuple[str, ...]]]] = []
    for line in header:
        p = line.split()
        if not p:
            continue
        if p[0] == "format":
            fmt = p[1]
        elif p[0] == "element":
            elements.append((p[1], int(p[2]), []))
        elif p[0] == "property" and elements:
            elements[-1][2].append(tuple(p[1:]))
    if fmt == "ascii":
        tokens = data[body_start:].split()
        pos = 0
        verts = np.zeros((0, 3))
        faces: list[list[int]] = []
        for name, count, props in elements:
            if name == "vertex":
                width = len(props)
                block = np.asarray(tokens[pos : pos + count * width], dtype=np.float64).reshape(count, width)
                names = [pr[-1] for pr in props]
                verts = block[:, [names.index("x"), names.index("y"), names.index("z")]]
                pos += count * width
            else:
                for _ in range(count):
                    for pr in props:
                        if pr[0] == "list":
                            k = int(tokens[pos])
                            if name == "face":
                                faces.append([int(t) for t in tokens[pos + 1 : pos + 1 + k]])
                            pos += 1 + k
                        else:
                            pos += 1
        return verts, _fan(faces)
    order = "<" if fmt == "binary_little_endian" else ">"
    offset = body_start
    verts = np.zeros((0, 3))
    faces = []
    for name, count, props in elements:
        if all(pr[0] != "list" for pr in props):
            dtype = np.dtype([(pr[1], order + _PLY_TYPES[pr[0]]) for pr in props])
            rec = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            offset += dtype.itemsize * count
            if name == "vertex":
                verts = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)
            continue
        for _ in range(count):
            for pr in props:
                if pr[0] == "list":
                    ct = np.dtype(order + _PLY_TYPES[pr[1]])
                    it = np.dtype(order + _PLY_TYPES[pr[2]])
                    k = int(np.frombuffer(data, ct, 1, offset)[0])
                    offset += ct.itemsize
                    idx = np.frombuffer(data, it, k, offset)
                    offset += it.itemsize * k
                    if name == "face":
                        faces.append(idx.astype(int).tolist())
                else:
                    offset += np.dtype(_PLY_TYPES[pr[0]]).itemsize
    return verts, _fan(faces)
