"""Triangle meshes from .obj and .ply (ascii and binary) files, read with numpy: for mesh
colliders and bodies (dynamics), for bind and key meshes (deformation), and for the
validation stage, which opens every mesh a scene names before any task starts.
Vertices stay in file order; polygons are fan-triangulated. Returns vertices [v, 3] and
triangle indices [t, 3]. (The renderer reads meshes through Mitsuba and its asset cache.)

Reading is strict, so that a mesh that would fail (or render wrong) in a worker fails
here instead, with the line or element at fault: at least one vertex and one face, finite
coordinates, indices inside the vertex list, and, for PLY, declared element counts that
match the bytes of the file (a truncated file is refused). The file must be a regular
file of at most MAX_MESH_BYTES.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .errors import AssetError, MeshFormatError
from .limits import FLOAT32_MAX, MAX_MESH_BYTES, beyond_float32

MAX_POLYGON = 256  # vertices of one face

_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4", "float": "f4", "double": "f8",
              "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2", "int32": "i4", "uint32": "u4", "float32": "f4", "float64": "f8"}


def cache_entry_whole(path: Path, full: bool = False) -> bool:
    """Whether a cache entry reads back whole: non-empty, and a PLY as a mesh (faces
    optional: morph targets have none). `full=True` (before an entry is published) reads
    the whole mesh; otherwise (on every hit) a binary PLY's size must equal what its header
    declares with triangle faces, as both cache writers write them (a 1M-vertex entry: a
    header read, not 5 s of parsing). An entry cut short or damaged after it was written (a
    crash of another tool, a disk that lost it) is then made again instead of failing every
    later run."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size == 0:
            return False
        if path.suffix.lower() != ".ply":
            return True
        if not full:
            with open(path, "rb") as fh:
                expected = _binary_ply_size(fh.read(1 << 16))
            if expected is not None:
                return expected == size
        load_mesh(path, faces=False)
    except (OSError, AssetError):
        return False
    return True


def _binary_ply_size(head: bytes) -> int | None:
    """The size in bytes of a binary PLY whose header is in `head`, its lists being
    triangles; None for an ASCII PLY. MeshFormatError for a header that does not parse."""
    fmt, elements, body_start = _ply_header(head)
    if fmt == "ascii":
        return None
    size = body_start
    for _name, count, props in elements:
        item = 0
        for pr in props:
            if pr[0] == "list":
                item += np.dtype(_PLY_TYPES[pr[1]]).itemsize + 3 * np.dtype(_PLY_TYPES[pr[2]]).itemsize
            else:
                item += np.dtype(_PLY_TYPES[pr[0]]).itemsize
        size += item * count
    return size


def load_mesh(path: Path, faces: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of an .obj or .ply file; AssetError with the reason if the file
    is unreadable, malformed, truncated, or has non-finite vertices or bad indices.
    `faces=False` accepts positions only (morph targets, blend-shape keys: their topology
    is the base mesh's)."""
    from .limits import read_bounded

    path = Path(path)
    data = read_bounded(path, MAX_MESH_BYTES, "mesh file", AssetError)
    try:
        if path.suffix.lower() == ".obj":
            verts, tris = _load_obj(data)
        else:
            verts, tris = _load_ply(data)
        _check(verts, tris, faces)
    except MeshFormatError as exc:
        raise AssetError(f"{path}: {exc}") from None
    except (ValueError, IndexError, KeyError, OverflowError, MemoryError) as exc:
        raise AssetError(f"{path}: cannot read mesh: {exc}") from None
    return verts, tris


class RenderMesh(NamedTuple):
    """A mesh as the renderer draws it: one render vertex per distinct (position, uv,
    normal) corner of the file. `index` [R]: the file vertex (position, in `load_mesh`
    order) of each render vertex, so deformed positions map onto it; `uvs` [R, 2] in
    Mitsuba's convention (v = 0 at the image's top: an OBJ `vt` is flipped as Mitsuba's own
    OBJ reader flips it), `normals` [R, 3]: the file's, or None where it has none."""

    index: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None
    normals: np.ndarray | None


def plain_render_mesh(count: int, faces: np.ndarray) -> RenderMesh:
    """A mesh without texture coordinates or normals: render vertex i is vertex i."""
    return RenderMesh(np.arange(count), np.asarray(faces, np.int64).reshape(-1, 3), None, None)


def load_render_mesh(path: Path) -> RenderMesh:
    """The render vertices of an .obj or .ply file (`RenderMesh`); the same checks and
    errors as `load_mesh`. OBJ corners are welded as Mitsuba's OBJ reader welds them, one
    render vertex per distinct (v, vt, vn); PLY vertices are render vertices (u, v or s, t
    and nx, ny, nz properties where present)."""
    from .limits import read_bounded

    path = Path(path)
    data = read_bounded(path, MAX_MESH_BYTES, "mesh file", AssetError)
    try:
        if path.suffix.lower() == ".obj":
            verts, vt, vn, corners = _parse_obj(data)
            _check(verts, _fan([[c[0] for c in face] for face in corners]))
            weld: dict[tuple[int, int, int], int] = {}
            polygons = [[weld.setdefault(c, len(weld)) for c in face] for face in corners]
            triples = np.asarray(list(weld), dtype=np.int64).reshape(-1, 3)
            uvs = normals = None
            if len(vt) and (triples[:, 1] >= 0).all():
                uvs = vt[triples[:, 1]] * [1.0, -1.0] + [0.0, 1.0]
            if len(vn) and (triples[:, 2] >= 0).all():
                normals = vn[triples[:, 2]]
            return _checked_attributes(RenderMesh(triples[:, 0], _fan(polygons), uvs, normals))
        columns, tris = _read_ply(data)
        verts = np.stack([columns["x"], columns["y"], columns["z"]], axis=1)
        _check(verts, tris)
        uv_names = next((pair for pair in (("u", "v"), ("s", "t"), ("texture_u", "texture_v")) if all(n in columns for n in pair)), None)
        uvs = np.stack([columns[n] for n in uv_names], axis=1) if uv_names else None
        normals = np.stack([columns[n] for n in ("nx", "ny", "nz")], axis=1) if all(n in columns for n in ("nx", "ny", "nz")) else None
        return _checked_attributes(RenderMesh(np.arange(len(verts)), tris, uvs, normals))
    except MeshFormatError as exc:
        raise AssetError(f"{path}: {exc}") from None
    except (ValueError, IndexError, KeyError, OverflowError, MemoryError) as exc:
        raise AssetError(f"{path}: cannot read mesh: {exc}") from None


def _checked_attributes(mesh: RenderMesh) -> RenderMesh:
    """The mesh, if its texture coordinates and normals are finite in float32."""
    for name, values in (("texture coordinate", mesh.uvs), ("normal", mesh.normals)):
        if values is not None:
            bad = beyond_float32(values).any(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                raise MeshFormatError(f"{name} of render vertex {i} is not finite in the renderer's float32 ({', '.join(f'{c:g}' for c in values[i])})")
    return mesh


def _check(verts: np.ndarray, tris: np.ndarray, faces: bool = True) -> None:
    if len(verts) == 0:
        raise MeshFormatError("the mesh has no vertices")
    if faces and len(tris) == 0:
        raise MeshFormatError("the mesh has no faces")
    bad = beyond_float32(verts).any(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise MeshFormatError(f"vertex {i} is not finite in the renderer's float32 ({', '.join(f'{c:g}' for c in verts[i])})")
    out = (tris < 0) | (tris >= len(verts))
    if out.any():
        t = int(np.argmax(out.any(axis=1)))
        raise MeshFormatError(f"face {t} refers to vertex {int(tris[t][out[t]][0])}; the mesh has {len(verts)} vertices (0-based)")


def _fan(polygons: list[list[int]]) -> np.ndarray:
    tris = [(p[0], p[i], p[i + 1]) for p in polygons for i in range(1, len(p) - 1)]
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def _load_obj(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    verts, _, _, faces = _parse_obj(data, attributes=False)
    return verts, _fan(faces)  # type: ignore[arg-type]


# every statement of the OBJ format (Wavefront's spec): a file whose first statement is none
# of these is not an OBJ file, whatever its name
_OBJ_STATEMENTS = frozenset("v vt vn vp f l p o g s mg usemtl mtllib cstype deg bmat step curv curv2 surf parm trim hole scrv sp end "
                            "con lod maplib usemap c_interp d_interp trace_obj shadow_obj bevel call csh ctech stech".split())
_SIGNATURES = ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"v/1\x01", "an OpenEXR image"), (b"GIF8", "a GIF image"),
               (b"ply", "a PLY mesh"), (b"glTF", "a binary glTF"), (b"PK\x03\x04", "a zip archive"), (b"#?RADIANCE", "a Radiance HDR image"))


def _not_obj(data: bytes) -> str | None:
    """Why `data` is not an OBJ file (what it starts with), or None when it may be one: a
    binary file (a NUL byte, a known signature), or text whose first statement is not an
    OBJ statement."""
    head = data[:4096]
    kind = next((what for sig, what in _SIGNATURES if head.startswith(sig)), None)
    if kind is not None or b"\0" in head:
        return f"not an OBJ mesh (it starts with {head[:8]!r}{': ' + kind if kind else ', binary data'})"
    for line in head.decode("utf-8", errors="replace").splitlines():
        word = line.split(maxsplit=1)[0] if line.split() else ""
        if not word or word.startswith("#"):
            continue
        if word not in _OBJ_STATEMENTS:
            return f"not an OBJ mesh (it starts with {line.strip()[:40]!r}, not an OBJ statement such as v or f)"
        return None
    return None


def _parse_obj(data: bytes, attributes: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[list[Any]]]:
    """Positions [v, 3], texture coordinates [vt, 2], normals [vn, 3] and each polygon's
    corners as 0-based (v, vt, vn) triples (-1: none given). Without `attributes` (the
    positions-only readers, twice as fast on a large file): no vt / vn values, and corners
    as their vertex index alone; the indices are checked either way."""
    why = _not_obj(data)
    if why is not None:
        raise MeshFormatError(why)
    verts: list[list[float]] = []
    faces: list[list[Any]] = []
    counts = {"vt": 0, "vn": 0}
    extra: dict[str, list[list[float]]] = {"vt": [], "vn": []}
    for number, line in enumerate(data.decode("utf-8", errors="replace").splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise MeshFormatError(f"line {number}: a vertex needs x y z, got {line.strip()!r}")
            try:
                xyz = [float(c) for c in parts[1:4]]
            except ValueError:
                raise MeshFormatError(f"line {number}: vertex coordinates are not numbers: {line.strip()[:80]!r}") from None
            if not all(math.isfinite(c) and abs(c) <= FLOAT32_MAX for c in xyz):
                raise MeshFormatError(f"line {number}: vertex {len(verts)} is not finite: {line.strip()[:80]!r}")
            verts.append(xyz)
        elif parts[0] in counts:
            counts[parts[0]] += 1
            if not attributes:
                continue
            width = 2 if parts[0] == "vt" else 3
            try:
                values = [float(c) for c in parts[1 : 1 + width]]
            except ValueError:
                raise MeshFormatError(f"line {number}: {parts[0]} values are not numbers: {line.strip()[:80]!r}") from None
            extra[parts[0]].append((values + [0.0] * width)[:width])
        elif parts[0] == "f":
            if not 4 <= len(parts) <= MAX_POLYGON + 1:
                raise MeshFormatError(f"line {number}: a face needs 3 to {MAX_POLYGON} vertices, got {len(parts) - 1}")
            idx: list[Any] = []
            for p in parts[1:]:
                refs = p.split("/")
                try:
                    nums = [int(r) if r else None for r in refs[:3]]
                except ValueError:
                    raise MeshFormatError(f"line {number}: face index {p!r} is not an integer") from None
                for value, have, what in zip(nums, (len(verts), counts["vt"], counts["vn"]), ("vertex", "texture coordinate", "normal")):
                    if value is None:
                        continue
                    if value == 0 or abs(value) > have or (value > 0 and value > have):
                        raise MeshFormatError(f"line {number}: face refers to {what} {value}; {have} are defined before it")
                v = nums[0]
                if v is None:
                    raise MeshFormatError(f"line {number}: face index {p!r} has no vertex")
                if not attributes:
                    idx.append(v - 1 if v > 0 else len(verts) + v)
                    continue
                nums += [None] * (3 - len(nums))
                have = (len(verts), counts["vt"], counts["vn"])
                corner = tuple(-1 if n is None else (n - 1 if n > 0 else h + n) for n, h in zip(nums, have))
                idx.append(corner)  # type: ignore[arg-type]
            faces.append(idx)
    vt = np.asarray(extra["vt"], dtype=np.float64).reshape(-1, 2)
    vn = np.asarray(extra["vn"], dtype=np.float64).reshape(-1, 3)
    return np.asarray(verts, dtype=np.float64).reshape(-1, 3), vt, vn, faces


def _load_ply(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    columns, tris = _read_ply(data)
    return np.stack([columns["x"], columns["y"], columns["z"]], axis=1), tris


def _ply_header(data: bytes) -> tuple[str, list[tuple[str, int, list[tuple[str, ...]]]], int]:
    """(format, elements as (name, count, properties), offset of the body) of a PLY file."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshFormatError("not a PLY file (no 'ply' magic or no end_header)")
    nl = data.find(b"\n", end)
    if nl < 0:
        raise MeshFormatError("the file ends inside its header")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    body_start = nl + 1
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, ...]]]] = []
    for line in header:
        p = line.split()
        if not p:
            continue
        if p[0] == "format":
            if len(p) < 2 or p[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise MeshFormatError(f"unknown PLY format {' '.join(p[1:])!r}")
            fmt = p[1]
        elif p[0] == "element":
            if len(p) != 3 or not p[2].isdigit() or len(p[2]) > 12:
                raise MeshFormatError(f"header line {line.strip()!r}: expected 'element NAME COUNT'")
            elements.append((p[1], int(p[2]), []))
        elif p[0] == "property" and elements:
            types = p[2:4] if p[1:2] == ["list"] else p[1:2]
            if len(p) < (5 if p[1:2] == ["list"] else 3) or any(t not in _PLY_TYPES for t in types):
                raise MeshFormatError(f"header line {line.strip()!r}: unknown property type")
            elements[-1][2].append(tuple(p[1:]))
    if fmt is None:
        raise MeshFormatError("the PLY header has no format line")
    return fmt, elements, body_start


def _read_ply(data: bytes) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The vertex element's properties by name (float64 columns) and the triangles."""
    fmt, elements, body_start = _ply_header(data)
    vertex = [e for e in elements if e[0] == "vertex"]
    if not vertex:
        raise MeshFormatError("the PLY file has no vertex element")
    names = [pr[-1] for pr in vertex[0][2]]
    if not all(c in names for c in "xyz"):
        raise MeshFormatError("the PLY vertex element has no x, y, z properties")
    if fmt == "ascii":
        return _ply_ascii(data[body_start:], elements)
    return _ply_binary(data, body_start, elements, "<" if fmt == "binary_little_endian" else ">")


def _ply_ascii(body: bytes, elements: list[tuple[str, int, list[tuple[str, ...]]]]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    tokens = body.split()
    pos = 0
    verts: dict[str, np.ndarray] = {}
    faces: list[list[int]] = []

    def need(n: int, name: str) -> None:
        if pos + n > len(tokens):
            raise MeshFormatError(f"the file is truncated: element '{name}' needs more values than the file holds")

    for name, count, props in elements:
        if all(pr[0] != "list" for pr in props):
            width = len(props)
            need(count * width, name)
            block = np.asarray(tokens[pos : pos + count * width], dtype=np.float64).reshape(count, width)
            if name == "vertex":
                verts = {pr[-1]: block[:, i] for i, pr in enumerate(props)}
            pos += count * width
            continue
        for _ in range(count):
            for pr in props:
                need(1, name)
                if pr[0] == "list":
                    k = int(tokens[pos])
                    if k < 0 or k > MAX_POLYGON:
                        raise MeshFormatError(f"element '{name}': a list of {k} values (at most {MAX_POLYGON})")
                    need(1 + k, name)
                    if name == "face":
                        faces.append([int(t) for t in tokens[pos + 1 : pos + 1 + k]])
                    pos += 1 + k
                else:
                    pos += 1
    if pos != len(tokens):
        raise MeshFormatError(f"{len(tokens) - pos} values after the last declared element (the declared counts do not match the data)")
    return verts, _fan(faces)


def _ply_binary(data: bytes, offset: int, elements: list[tuple[str, int, list[tuple[str, ...]]]], order: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    verts: dict[str, np.ndarray] = {}
    faces: list[list[int]] = []
    size = len(data)
    for name, count, props in elements:
        if all(pr[0] != "list" for pr in props):
            dtype = np.dtype([(pr[1], order + _PLY_TYPES[pr[0]]) for pr in props])
            if offset + dtype.itemsize * count > size:
                raise MeshFormatError(
                    f"the file is truncated: element '{name}' declares {count} items of {dtype.itemsize} bytes, "
                    f"{max(0, size - offset)} bytes are left"
                )
            rec = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            offset += dtype.itemsize * count
            if name == "vertex":
                verts = {pr[1]: rec[pr[1]].astype(np.float64) for pr in props}
            continue
        for item in range(count):
            for pr in props:
                if pr[0] == "list":
                    ct = np.dtype(order + _PLY_TYPES[pr[1]])
                    it = np.dtype(order + _PLY_TYPES[pr[2]])
                    if offset + ct.itemsize > size:
                        raise MeshFormatError(f"the file is truncated: element '{name}' item {item} of {count}")
                    k = int(np.frombuffer(data, ct, 1, offset)[0])
                    offset += ct.itemsize
                    if k < 0 or k > MAX_POLYGON:
                        raise MeshFormatError(f"element '{name}' item {item}: a list of {k} values (at most {MAX_POLYGON})")
                    if offset + it.itemsize * k > size:
                        raise MeshFormatError(f"the file is truncated: element '{name}' item {item} of {count}")
                    idx = np.frombuffer(data, it, k, offset)
                    offset += it.itemsize * k
                    if name == "face":
                        faces.append(idx.astype(np.int64).tolist())
                else:
                    offset += np.dtype(_PLY_TYPES[pr[0]]).itemsize
                    if offset > size:
                        raise MeshFormatError(f"the file is truncated: element '{name}' item {item} of {count}")
    trailing = data[offset:]
    if trailing.strip():
        raise MeshFormatError(f"{len(trailing)} bytes after the last declared element (the declared counts do not match the data)")
    return verts, _fan(faces)


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The engine's vertex normals [R, 3] of a triangle mesh (`positions` [R, 3] of its
    render vertices, `faces` [F, 3]): Mitsuba 3.9's `Mesh::recompute_vertex_normals`, which
    its OBJ and PLY readers apply to a static mesh without normals - per render vertex, the
    unit normals of the faces around it weighted by the face's angle at that corner
    (Thuermer & Wuethrich 1998), normalised; a face without area adds nothing and a vertex
    left with nothing gets (1, 0, 0), as Mitsuba's. Equal to Mitsuba's to float rounding
    (tests/render/test_assets.py); the asset cache writes them into a static mesh without file normals (render/translate/assets.py) and the slices of a deforming one (render/translate/deforming.py); summed in face order (np.bincount), so the bits never
    depend on the thread count - Mitsuba's own, an atomic scatter-add across drjit's
    threads, differs from run to run in the last bit on a 65k-triangle mesh."""
    p = np.asarray(positions, np.float32)
    f = np.asarray(faces)
    a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    ab, bc, ca = b - a, c - b, a - c
    cross = np.cross(ab, -ca)  # the face normal, |.| = twice the area
    double_area = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    # each corner's angle between the edges leaving it (slot 0: ab, -ca; 1: bc, -ab; 2: ca, -bc),
    # as atan2(|e1 x e2|, e1 . e2): Mitsuba's acos of the unit edges' dot, without normalising them
    dots = -np.stack([np.einsum("ij,ij->i", ab, ca), np.einsum("ij,ij->i", bc, ab), np.einsum("ij,ij->i", ca, bc)])
    weight = np.divide(np.arctan2(double_area, dots), double_area, out=np.zeros_like(dots), where=double_area > 0)
    weighted = (cross[None, :, :] * weight[:, :, None]).reshape(-1, 3)  # [3 slots x F, 3]: unit normal x angle
    corners = f.T.ravel()
    acc = np.stack([np.bincount(corners, weighted[:, axis], minlength=len(p)) for axis in range(3)], axis=1)
    length = np.sqrt(np.einsum("ij,ij->i", acc, acc))[:, None]
    return np.where(length > 0, acc / np.where(length > 0, length, 1.0), np.array([1.0, 0.0, 0.0]))
