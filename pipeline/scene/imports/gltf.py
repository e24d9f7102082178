"""glTF 2.0 (.gltf, .glb) -> scene records (docs/imports.md).

pygltflib reads the container (JSON, GLB chunks) into its dataclasses; accessors are
decoded here with numpy (pygltflib leaves them as bytes), with every range checked
against its buffer view and buffer, so a bad file is a located error, never a crash or
an out-of-bounds read. Nodes become parent frames (empties or meshes), meshes go to the
asset cache as binary PLY, animation channels become keyframe tracks (STEP -> hold,
LINEAR -> linear with slerp, CUBICSPLINE -> hermite with the file's tangents), skins
become `joint-skin` deformations driven by the joint nodes' world frames, morph targets
become `morph-targets` deformations.
"""

from __future__ import annotations

import base64
import math
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ..files import bytes_digest, file_digest
from ...errors import InputFileError
from ...limits import MAX_GLTF_BYTES as MAX_FILE_BYTES  # refuse absurd files before reading them
from ...limits import MAX_GLTF_KEYS, MAX_IMAGE_BYTES, read_bounded
from .expansion import Expansion, ImportFileError, Origin, SpecError, import_frames
from .converted import cached, write_atomic, write_ply

COMPONENTS = {5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"), 5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4")}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
NORMALISED = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
# Extensions we read; any other one a file marks required is refused.
SUPPORTED_EXTENSIONS = ("KHR_lights_punctual", "KHR_materials_emissive_strength")
MODES = {"STEP": "hold", "LINEAR": "linear", "CUBICSPLINE": "hermite"}
WRAP = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
# values one accessor may hold: a buffer view bounds the others by the file's size, but an
# accessor without one (zeros, then sparse values) would allocate whatever `count` says
MAX_ACCESSOR_VALUES = 1 << 25  # numbers in one accessor (11M VEC3 vertices; a 44M-vertex accessor was read whole)
MAX_NODES = 100_000  # nodes of one file (each becomes a scene record: 300k took minutes)


def sanitize(name: str) -> str:
    """A glTF / USD name as a scene name: [A-Za-z_][A-Za-z0-9_.-]*, at most 100 characters."""
    out = re.sub(r"[^A-Za-z0-9_.\-]", "_", name)[:100]
    return out if re.match(r"^[A-Za-z_]", out) else f"_{out}"


class _Names:
    """Unique scene names: the first use of a name keeps it, later ones get .1, .2 ..."""

    def __init__(self) -> None:
        self.used: set[str] = set()

    def take(self, name: str) -> str:
        out, k = name, 1
        while out in self.used:
            out, k = f"{name}.{k}", k + 1
        self.used.add(out)
        return out


def _floats(a: Any) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=np.float64).ravel()]


def _wxyz(xyzw: Any) -> list[float]:
    q = _floats(xyzw)
    return [q[3], q[0], q[1], q[2]]


class GltfReader:
    """One glTF file, read and checked; `expand()` makes the records."""

    def __init__(self, path: Path, shown: str, spec: Any, index: int, raw: bytes | None = None) -> None:
        import pygltflib

        self.path, self.shown, self.spec, self.index = path, shown, spec, index
        if raw is None or len(raw) > MAX_FILE_BYTES:  # `raw`: the file's bytes as its caller hashed them
            raw = self._read(path, MAX_FILE_BYTES, "glTF file", "<file>")
        if path.suffix.lower() == ".glb" or raw[:4] == b"glTF":
            self._check_glb(raw)
        self._check_counts(raw)
        try:
            self.gltf = pygltflib.GLTF2.load_from_bytes(raw) if raw[:4] == b"glTF" else pygltflib.GLTF2.from_json(raw.decode("utf-8"))
        except Exception as exc:  # pygltflib raises whatever its parser raised
            self.fail("<file>", f"not a readable glTF 2.0 file: {type(exc).__name__}: {exc}")
        if self.gltf is None:
            self.fail("<file>", "not a readable glTF 2.0 file")
        self.glb_blob = self.gltf.binary_blob() if raw[:4] == b"glTF" else None
        version = str(getattr(self.gltf.asset, "version", "") or "")
        if not version.startswith("2."):
            self.fail("asset.version", f"glTF {version or '?'} is not supported; expected 2.x")
        for ext in self.gltf.extensionsRequired or []:
            if ext not in SUPPORTED_EXTENSIONS:
                self.fail("extensionsRequired", f"unsupported extension '{ext}' is marked required (supported: {', '.join(SUPPORTED_EXTENSIONS)})")
        self._buffers: dict[int, bytes] = {}
        self._keys = 0  # animation keys read so far (MAX_GLTF_KEYS)
        self.digest = source_digest(path, raw)  # the bytes read, not the file as it is now
        self.at = "<file>"  # what is being read: the location of an unforeseen malformation

    # --- errors and raw data ------------------------------------------------------------

    def fail(self, where: str, message: str) -> "None":
        """Raise ImportFileError at `where` in the file."""
        raise ImportFileError(self.shown, where, message)

    def _read(self, file: Path, limit: int, what: str, where: str) -> bytes:
        """A file of the import read whole, refused unread when it is no regular file or is
        over `limit` bytes (a FIFO hung; a 5 GB buffer beside the file was a MemoryError)."""
        try:
            return read_bounded(file, limit, what)
        except InputFileError as exc:
            self.fail(where, exc.reason)
        raise AssertionError("unreachable")  # (fail raises)

    def _check_counts(self, raw: bytes) -> None:
        """The document's sizes, from a plain JSON parse (fast), before pygltflib builds an
        object per element (300,000 nodes took it over a minute)."""
        import json

        try:
            text = raw[20 : 20 + struct.unpack_from("<I", raw, 12)[0]] if raw[:4] == b"glTF" else raw
            doc = json.loads(text)
        except (ValueError, struct.error, RecursionError) as exc:
            self.fail("<file>", f"not a readable glTF 2.0 file: {type(exc).__name__}: {str(exc)[:120]}")
        if not isinstance(doc, dict):
            self.fail("<file>", "not a readable glTF 2.0 file (the top level is not an object)")
        for key in ("nodes", "accessors", "meshes", "animations", "materials", "images"):
            items = doc.get(key)
            if isinstance(items, list) and len(items) > MAX_NODES:
                self.fail(key, f"{len(items)} {key}; the limit is {MAX_NODES}")

    def _check_glb(self, raw: bytes) -> None:
        if len(raw) < 12:
            self.fail("<glb header>", f"truncated .glb: {len(raw)} bytes, the header alone is 12")
        magic, version, length = struct.unpack_from("<4sII", raw, 0)
        if magic != b"glTF":
            self.fail("<glb header>", "not a .glb file (magic is not 'glTF')")
        if version != 2:
            self.fail("<glb header>", f"GLB container version {version}; expected 2")
        if length != len(raw):
            self.fail("<glb header>", f"truncated .glb: the header says {length} bytes, the file has {len(raw)}")
        offset = 12
        while offset < len(raw):
            if offset + 8 > len(raw):
                self.fail(f"<glb chunk at byte {offset}>", "truncated chunk header")
            chunk_len, _ = struct.unpack_from("<II", raw, offset)
            if offset + 8 + chunk_len > len(raw):
                self.fail(f"<glb chunk at byte {offset}>", f"chunk of {chunk_len} bytes runs past the end of the file")
            offset += 8 + chunk_len

    def buffer(self, i: int) -> bytes:
        """The bytes of buffer `i` (the GLB chunk, a data URI or a file beside the glTF), read once."""
        if i in self._buffers:
            return self._buffers[i]
        buffers = self.gltf.buffers or []
        if not 0 <= i < len(buffers):
            self.fail(f"buffers[{i}]", "no such buffer")
        buf = buffers[i]
        where = f"buffers[{i}]"
        if not isinstance(buf.byteLength, int) or not 0 <= buf.byteLength <= MAX_FILE_BYTES:
            self.fail(where, f"byteLength {buf.byteLength} is out of range (at most {MAX_FILE_BYTES} bytes)")
        if buf.uri is None:
            if i != 0 or self.glb_blob is None:
                self.fail(where, "a buffer without uri must be the GLB binary chunk (buffer 0 of a .glb)")
            data = self.glb_blob
        elif buf.uri.startswith("data:"):
            try:
                data = base64.b64decode(buf.uri.split(",", 1)[1], validate=True)
            except (ValueError, IndexError) as exc:
                self.fail(where, f"bad data URI: {exc}")
        else:
            file = self.path.parent / buf.uri
            if not file.exists():
                self.fail(f"{where} '{buf.uri}'", f"file not found (relative to {self.path.parent})")
            data = self._read(file, MAX_FILE_BYTES, "buffer file", f"{where} '{buf.uri}'")
        if len(data) < (buf.byteLength or 0):
            self.fail(where, f"has {len(data)} bytes; byteLength says {buf.byteLength} (truncated?)")
        self._buffers[i] = data
        return data

    def _view(self, v: int, where: str) -> tuple[bytes, int, int, int | None]:
        views = self.gltf.bufferViews or []
        if not 0 <= v < len(views):
            self.fail(where, f"bufferView {v} does not exist")
        bv = views[v]
        data = self.buffer(bv.buffer)
        start = bv.byteOffset or 0
        if start + bv.byteLength > len(data):
            self.fail(f"bufferViews[{v}]", f"bytes {start}..{start + bv.byteLength} run past the end of buffer {bv.buffer} ({len(data)} bytes)")
        return data, start, bv.byteLength, bv.byteStride

    def _strided(self, view: int, offset: int, count: int, dtype: np.dtype, width: int, where: str) -> np.ndarray:
        data, start, length, stride = self._view(view, where)
        elem = dtype.itemsize * width
        stride = stride or elem
        need = offset + stride * (count - 1) + elem if count else 0
        if need > length:
            self.fail(where, f"out of range: needs {need} bytes of bufferView {view}, which has {length}")
        return np.ndarray((count, width), dtype=dtype, buffer=data, offset=start + offset, strides=(stride, dtype.itemsize)).copy()

    def accessor(self, i: int | None, where: str = "") -> np.ndarray:
        """Accessor `i` as [count, width]: float64 (floats, normalised integers) or int64."""
        accessors = self.gltf.accessors or []
        self.at = f"accessors[{i}]" + (f" ({where})" if where else "")
        if not isinstance(i, int) or not 0 <= i < len(accessors):
            self.fail(where or f"accessors[{i}]", f"accessor {i} does not exist")
        a = accessors[i]
        at = f"accessors[{i}]" + (f" ({where})" if where else "")
        dtype = COMPONENTS.get(a.componentType)
        width = WIDTHS.get(a.type)
        if dtype is None or width is None:
            self.fail(at, f"unknown componentType {a.componentType} or type {a.type}")
        if not isinstance(a.count, int) or a.count < 0 or a.count * width > MAX_ACCESSOR_VALUES:
            self.fail(at, f"count {a.count} is out of range (at most {MAX_ACCESSOR_VALUES // width} elements of {a.type})")
        if a.bufferView is None:
            out = np.zeros((a.count, width), dtype=dtype)
        else:
            out = self._strided(a.bufferView, a.byteOffset or 0, a.count, dtype, width, at)
        if a.sparse is not None:
            sp = a.sparse
            # the specification: unsigned byte/short/int indices, strictly increasing (a signed
            # -1 would write the last element through numpy's negative indexing)
            idx_dtype = COMPONENTS.get(sp.indices.componentType) if sp.indices.componentType in (5121, 5123, 5125) else None
            if idx_dtype is None or not isinstance(sp.count, int) or not 1 <= sp.count <= a.count:
                self.fail(f"{at}.sparse", f"bad sparse indices (componentType {sp.indices.componentType}, count {sp.count}): "
                                          "expected 1 to count unsigned byte, short or int indices")
            idx = self._strided(sp.indices.bufferView, sp.indices.byteOffset or 0, sp.count, idx_dtype, 1, f"{at}.sparse.indices")[:, 0].astype(np.int64)
            vals = self._strided(sp.values.bufferView, sp.values.byteOffset or 0, sp.count, dtype, width, f"{at}.sparse.values")
            if len(idx) and int(idx.max()) >= a.count:
                self.fail(f"{at}.sparse.indices", f"index {int(idx.max())} is out of range for {a.count} elements")
            if (np.diff(idx) <= 0).any():
                k = int(np.argmax(np.diff(idx) <= 0)) + 1
                self.fail(f"{at}.sparse.indices", f"index {int(idx[k])} at position {k} does not follow {int(idx[k - 1])}: sparse indices must strictly increase")
            out = out.copy()
            out[idx] = vals
        if dtype.kind == "f":
            result = out.astype(np.float64)
            if not np.isfinite(result).all():
                self.fail(at, "contains a non-finite value (NaN or infinity)")
            return result
        if a.normalized:
            return np.maximum(out.astype(np.float64) / NORMALISED[a.componentType], -1.0)
        return out.astype(np.int64)

    # --- the node tree ------------------------------------------------------------------

    def expand(self) -> Expansion:
        """The records of the import: objects (meshes, skins, morph targets, animation), materials, lights and cameras."""
        g, spec = self.gltf, self.spec
        nodes = g.nodes or []
        if len(nodes) > MAX_NODES:
            self.fail("nodes", f"{len(nodes)} nodes; the limit is {MAX_NODES}")
        roots = self._scene_roots(nodes)
        parent = self._parents(nodes)
        if spec.nodes is not None:
            roots = self._named_nodes(nodes)
        order = self._tree_order(nodes, roots)
        included = set(order)

        names = _Names()
        prefix = spec.prefix
        ex = Expansion()
        # glTF is metres and +Y up, as we are: a stage frame only where the entry overrides
        frames, root_name = import_frames(names.take, spec, self.index, self.shown, f"{prefix}{sanitize(self.path.stem)}")
        node_name = {k: names.take(prefix + sanitize(nodes[k].name or f"node{k}")) for k in order}
        ex.objects.extend(frames)
        self.names, self.node_name, self.root_name, self.prefix = names, node_name, root_name, prefix
        self.material_names: dict[int | None, str] = {}
        self.motions = self._animations(included)
        for k in order:
            par = node_name[parent[k]] if k in parent and parent[k] in included and k not in roots else root_name
            self._node_records(k, nodes[k], par, ex)
        for m_index, m_name in self.material_names.items():
            ex.materials.append((self._material(m_index, m_name), Origin(self.shown, f"materials[{m_index}]" if m_index is not None else "<default material>")))
        return ex

    def _scene_roots(self, nodes: list[Any]) -> list[int]:
        """The root nodes of the scene the entry names (by name or index), else the file's
        default scene, else (no scenes) every node that is no node's child."""
        g, spec = self.gltf, self.spec
        scenes = g.scenes or []
        if isinstance(spec.scene, str):
            matches = [k for k, s in enumerate(scenes) if s.name == spec.scene]
            if not matches:
                raise SpecError("scene", f"no scene named '{spec.scene}' in {self.shown} (scenes: {', '.join(str(s.name) for s in scenes) or 'none'})")
            scene_index: int | None = matches[0]
        else:
            scene_index = spec.scene if spec.scene is not None else (g.scene if g.scene is not None else (0 if scenes else None))
        if scene_index is not None and not 0 <= scene_index < len(scenes):
            raise SpecError("scene", f"scene {scene_index} does not exist in {self.shown} ({len(scenes)} scenes)")
        roots = list(scenes[scene_index].nodes or []) if scene_index is not None else [k for k in range(len(nodes)) if not any(k in (n.children or []) for n in nodes)]
        for r in roots:
            if not 0 <= r < len(nodes):
                self.fail(f"scenes[{scene_index}].nodes", f"node {r} does not exist")
        return roots

    def _parents(self, nodes: list[Any]) -> dict[int, int]:
        """Each child node's parent, and a check that the children form a tree."""
        parent: dict[int, int] = {}
        for k, n in enumerate(nodes):
            for c in n.children or []:
                if not 0 <= c < len(nodes):
                    self.fail(f"nodes[{k}] '{n.name}'.children", f"node {c} does not exist")
                if c in parent or c == k:
                    self.fail(f"nodes[{c}] '{nodes[c].name}'", "has more than one parent (the nodes must form a tree)")
                parent[c] = k
        return parent

    def _named_nodes(self, nodes: list[Any]) -> list[int]:
        """The nodes the entry's `nodes:` names (by name or sanitised name), as roots."""
        wanted = []
        for name in self.spec.nodes:
            found = [k for k, n in enumerate(nodes) if n.name == name or sanitize(n.name or "") == name]
            if not found:
                raise SpecError("nodes", f"no node named '{name}' in {self.shown}")
            wanted.append(found[0])
        return wanted

    def _tree_order(self, nodes: list[Any], roots: list[int]) -> list[int]:
        """The nodes under `roots`, depth first, parents before children; a node reached
        twice is a problem."""
        order: list[int] = []
        stack = list(reversed(roots))
        seen: set[int] = set()
        while stack:
            k = stack.pop()
            if k in seen:
                self.fail(f"nodes[{k}] '{nodes[k].name}'", "is reachable twice (a cycle in children?)")
            seen.add(k)
            order.append(k)
            stack.extend(reversed(nodes[k].children or []))
        return order

    def _node_records(self, k: int, n: Any, par: str, ex: Expansion) -> None:
        """Node k's records into `ex`: an empty carrying its transform and motion under
        `par`, and its mesh objects, camera and KHR_lights_punctual light."""
        node_name = self.node_name
        where = f"nodes[{k}] '{n.name}'" if n.name else f"nodes[{k}]"
        self.at = where
        origin = Origin(self.shown, where)
        rec: dict[str, Any] = {"name": node_name[k], "shape": "empty", "parent": par, "transform": self._transform(n, where)}
        motion = self.motions.get(k, {}).get("transform")
        if motion:
            rec["motion"] = motion
        ex.objects.append((rec, origin))
        if n.mesh is not None:
            self._mesh_objects(k, n, rec, where, ex)
        if n.camera is not None:
            ex.cameras.append((n.name or node_name[k], self._camera(n.camera, node_name[k]), Origin(self.shown, f"cameras[{n.camera}] on {where}")))
        ext = (n.extensions or {}).get("KHR_lights_punctual")
        if ext is not None:
            light = self._light(ext, node_name[k], where)
            ex.lights.append((light, Origin(self.shown, f"KHR_lights_punctual.lights[{ext.get('light')}] on {where}")))

    def _transform(self, n: Any, where: str) -> dict[str, Any]:
        if n.matrix is not None and list(n.matrix) != [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]:
            m = np.asarray(n.matrix, dtype=np.float64).reshape(4, 4).T  # column-major in the file
            if not np.isfinite(m).all():
                self.fail(f"{where}.matrix", "non-finite value")
            a = m[:3, :3]
            s = np.linalg.norm(a, axis=0)
            if (s < 1e-12).any():
                self.fail(f"{where}.matrix", "a zero scale is not supported")
            r = a / s
            if np.linalg.det(r) < 0:
                self.fail(f"{where}.matrix", "a mirroring (negative determinant) transform is not supported")
            if np.abs(r.T @ r - np.eye(3)).max() > 1e-4:
                self.fail(f"{where}.matrix", "a sheared matrix is not supported (translate, rotate, scale only)")
            from scipy.spatial.transform import Rotation

            q = Rotation.from_matrix(r).as_quat()  # x, y, z, w
            return {"translate": _floats(m[:3, 3]), "rotate": {"quaternion": _wxyz(q)}, "scale": _floats(s)}
        out: dict[str, Any] = {}
        if n.translation is not None:
            out["translate"] = _floats(n.translation)
        if n.rotation is not None:
            out["rotate"] = {"quaternion": _wxyz(n.rotation)}
        if n.scale is not None:
            s = _floats(n.scale)
            if min(s) <= 0:
                self.fail(f"{where}.scale", f"scale {s}: zero or negative (mirroring) scale is not supported")
            out["scale"] = s
        return out

    # --- animation ----------------------------------------------------------------------

    def _animations(self, included: set[int]) -> dict[int, dict[str, Any]]:
        """Per node: {"transform": keyframes motion, "weights": (channel per target)}."""
        g, spec = self.gltf, self.spec
        anims = g.animations or []
        if not anims or spec.animation == -1:
            return {}
        targets = [{(ch.target.node, ch.target.path) for ch in a.channels or []} for a in anims]
        if spec.animation == "*":
            selected = list(range(len(anims)))
        elif isinstance(spec.animation, str):
            found = [k for k, a in enumerate(anims) if a.name == spec.animation]
            if not found:
                raise SpecError("animation", f"no animation named '{spec.animation}' in {self.shown} (animations: {', '.join(str(a.name) for a in anims)}; '*' plays them all)")
            selected = found[:1]
        elif spec.animation is not None:
            if spec.animation >= len(anims):
                raise SpecError("animation", f"animation {spec.animation} does not exist in {self.shown} ({len(anims)} animations)")
            selected = [spec.animation]
        else:
            # by default every animation plays when they key disjoint things (an exporter's
            # one animation per object, as Blender writes); takes of one rig: the first
            disjoint = sum(len(t) for t in targets) == len(set().union(*targets))
            selected = list(range(len(anims))) if disjoint else [0]
        out: dict[int, dict[str, Any]] = {}
        channels: dict[int, dict[str, Any]] = {}
        keyed: dict[tuple[int, str], int] = {}
        for a_index in selected:
            self._animation(anims[a_index], a_index, included, out, channels, keyed)
        for node, chans in channels.items():
            out.setdefault(node, {})["transform"] = {"type": "keyframes", "time_unit": "seconds", "extrapolation": "hold", "channels": chans}
        return out

    def _animation(self, anim: Any, a_index: int, included: set[int], out: dict[int, dict[str, Any]], channels: dict[int, dict[str, Any]], keyed: dict[tuple[int, str], int]) -> None:
        """The channels of one animation into `out` (weights) and `channels` (transforms)."""
        for c, ch in enumerate(anim.channels or []):
            self.at = f"animations[{a_index}].channels[{c}]"
            node = ch.target.node
            if node is None or node not in included:
                continue
            where = f"animations[{a_index}].channels[{c}]"
            first = keyed.setdefault((node, ch.target.path), a_index)
            if first != a_index or sum(1 for x in anim.channels if (x.target.node, x.target.path) == (node, ch.target.path)) > 1:
                self.fail(where, f"node {node} '{self.gltf.nodes[node].name}' {ch.target.path} is keyed twice (also in animations[{first}]); pick one with `animation`")
            samplers = anim.samplers or []
            if not 0 <= ch.sampler < len(samplers):
                self.fail(where, f"sampler {ch.sampler} does not exist")
            s = samplers[ch.sampler]
            swhere = f"animations[{a_index}].samplers[{ch.sampler}]"
            times = self.accessor(s.input, f"{swhere}.input")[:, 0]
            if len(times) == 0:
                self.fail(f"{swhere}.input", "no key times")
            self._keys += len(times)
            if self._keys > MAX_GLTF_KEYS:
                self.fail(f"{swhere}.input (accessor {s.input})", f"{self._keys} animation keys in this import so far; the limit is {MAX_GLTF_KEYS} "
                                                                  "(each key becomes a scene record: bake dense motion to a file, `motion render --motion`)")
            if (np.diff(times) <= 0).any():
                self.fail(f"{swhere}.input (accessor {s.input})", "key times must increase strictly")
            values = self.accessor(s.output, f"{swhere}.output")
            interp = s.interpolation or "LINEAR"
            if interp not in MODES:
                self.fail(f"{swhere}.interpolation", f"unknown interpolation '{interp}'")
            path = ch.target.path
            per_key = 3 if interp == "CUBICSPLINE" else 1
            if path == "weights":
                n_targets = len(values) // max(len(times) * per_key, 1)
                if n_targets * len(times) * per_key != len(values) or values.shape[1] != 1:
                    self.fail(f"{swhere}.output (accessor {s.output})", f"{len(values)} values do not fit {len(times)} keys of morph weights")
                vals = values[:, 0].reshape(len(times), per_key, n_targets)
                weights = {}
                for j in range(n_targets):
                    weights[j] = self._channel(times, vals[:, :, j : j + 1], interp, False)
                out.setdefault(node, {})["weights"] = weights
                continue
            width = {"translation": 3, "rotation": 4, "scale": 3}.get(path)
            if width is None:
                self.fail(f"{where}.target.path", f"unknown animation path '{path}'")
            if len(values) != len(times) * per_key or values.shape[1] != width:
                self.fail(f"{swhere}.output (accessor {s.output})", f"{len(values)} values of {values.shape[1]} for {len(times)} {interp} keys of {path}; expected {len(times) * per_key} of {width}")
            name = {"translation": "translate", "rotation": "rotate", "scale": "scale"}[path]
            channels.setdefault(node, {})[name] = self._channel(times, values.reshape(len(times), per_key, width), interp, path == "rotation")

    def _channel(self, times: np.ndarray, values: np.ndarray, interp: str, rotation: bool) -> dict[str, Any]:
        """values [n, 1 or 3 (in-tangent, value, out-tangent), width] -> a channel record."""
        mode = MODES[interp]
        cubic = values.shape[1] == 3
        keys = []
        conv = _wxyz if rotation else _floats
        for i, t in enumerate(times):
            v = values[i, 1] if cubic else values[i, 0]
            key: dict[str, Any] = {"time": float(t) + self.spec.time_offset}
            val = conv(v)
            if rotation:
                key["quaternion"] = val
            else:
                key["value"] = val if len(val) > 1 else val[0]
            if cubic:
                a, b = conv(values[i, 0]), conv(values[i, 2])
                key["tangent_in"] = a if len(a) > 1 else a[0]
                key["tangent_out"] = b if len(b) > 1 else b[0]
            keys.append(key)
        return {"interpolation": mode, "keys": keys}

    # --- meshes, skins, morph targets ---------------------------------------------------

    def _mesh_objects(self, k: int, n: Any, rec: dict[str, Any], where: str, ex: Expansion) -> None:
        meshes = self.gltf.meshes or []
        if not 0 <= n.mesh < len(meshes):
            self.fail(where, f"mesh {n.mesh} does not exist")
        mesh = meshes[n.mesh]
        prims = mesh.primitives or []
        skinned = n.skin is not None
        single = len(prims) == 1 and not skinned
        for p, prim in enumerate(prims):
            pwhere = f"meshes[{n.mesh}] '{mesh.name}'.primitives[{p}]" if mesh.name else f"meshes[{n.mesh}].primitives[{p}]"
            file, count = self._prim_ply(n.mesh, p, prim, pwhere)
            material = self._material_name(prim.material)
            if single:
                target = rec
                rec["shape"] = "mesh"
            else:
                suffix = "mesh" if len(prims) == 1 else f"mesh{p}"
                target = {"name": self.names.take(f"{rec['name']}.{suffix}"), "shape": "mesh", "parent": rec["name"]}
                if skinned:
                    # glTF: a skinned mesh ignores its node's transform; the joints place it
                    target["parent"] = self.root_name
                ex.objects.append((target, Origin(self.shown, f"{where} {pwhere}")))
            target["file"] = str(file)
            target["material"] = material
            emission = self._emission(prim.material)
            if emission is not None:
                target["emission"] = emission
            morph = self._morph(k, n, mesh, p, prim, count, pwhere)
            if skinned:
                target["deform"] = self._skin(k, n, p, prim, count, pwhere, morph)
            elif morph is not None:
                target["deform"] = morph

    def _prim_ply(self, m: int, p: int, prim: Any, where: str) -> tuple[Path, int]:
        mode = 4 if prim.mode is None else prim.mode
        if mode != 4:
            self.fail(f"{where}.mode", f"primitive mode {mode} is not supported (triangles, mode 4, only)")
        attrs = prim.attributes
        if attrs.POSITION is None:
            self.fail(f"{where}.attributes", "has no POSITION")
        count = self.gltf.accessors[attrs.POSITION].count if 0 <= attrs.POSITION < len(self.gltf.accessors or []) else -1
        if count < 0:
            self.fail(f"{where}.attributes.POSITION", f"accessor {attrs.POSITION} does not exist")

        def write(tmp: Path) -> None:
            pos = self.accessor(attrs.POSITION, f"{where}.attributes.POSITION")
            normals = self.accessor(attrs.NORMAL, f"{where}.attributes.NORMAL") if attrs.NORMAL is not None else None
            uvs = self.accessor(attrs.TEXCOORD_0, f"{where}.attributes.TEXCOORD_0") if attrs.TEXCOORD_0 is not None else None
            for name, arr, width in (("NORMAL", normals, 3), ("TEXCOORD_0", uvs, 2)):
                if arr is not None and (len(arr) != len(pos) or arr.shape[1] != width):
                    self.fail(f"{where}.attributes.{name}", f"{len(arr)} x {arr.shape[1]} values for {len(pos)} vertices")
            if prim.indices is not None:
                idx = self.accessor(prim.indices, f"{where}.indices")[:, 0]
            else:
                idx = np.arange(len(pos))
            if len(idx) % 3:
                self.fail(f"{where}.indices (accessor {prim.indices})", f"{len(idx)} indices is not a whole number of triangles")
            if len(idx) and (idx.min() < 0 or idx.max() >= len(pos)):
                self.fail(f"{where}.indices (accessor {prim.indices})", f"index {int(idx.max())} is out of range for {len(pos)} vertices")
            write_ply(tmp, pos, idx.reshape(-1, 3), normals, uvs)

        stem = f"{self.path.stem}-m{m}p{p}"
        return cached(stem, f"{self.digest}|mesh|{m}|{p}", ".ply", write), count

    def _morph(self, k: int, n: Any, mesh: Any, p: int, prim: Any, count: int, where: str) -> dict[str, Any] | None:
        targets = prim.targets or []
        if not targets:
            return None
        names_extra = (mesh.extras or {}).get("targetNames") if isinstance(mesh.extras, dict) else None
        weights = list(getattr(n, "weights", None) or mesh.weights or [0.0] * len(targets))
        if len(weights) != len(targets):
            self.fail(where, f"{len(weights)} default weights for {len(targets)} morph targets")
        out_targets = []
        tnames = []
        for j, target in enumerate(targets):
            tname = str(names_extra[j]) if names_extra and j < len(names_extra) else f"target{j}"
            tnames.append(tname)
            pos_acc = target.get("POSITION") if isinstance(target, dict) else getattr(target, "POSITION", None)
            if pos_acc is None:
                self.fail(f"{where}.targets[{j}]", "a morph target without POSITION is not supported")

            def write(tmp: Path, pos_acc: int = pos_acc, j: int = j) -> None:
                base = self.accessor(prim.attributes.POSITION, f"{where}.attributes.POSITION")
                delta = self.accessor(pos_acc, f"{where}.targets[{j}].POSITION")
                if delta.shape != base.shape:
                    self.fail(f"{where}.targets[{j}].POSITION (accessor {pos_acc})", f"{len(delta)} offsets for {len(base)} vertices")
                write_ply(tmp, base + delta, None)

            file = cached(f"{self.path.stem}-m{n.mesh}p{p}t{j}", f"{self.digest}|morph|{n.mesh}|{p}|{j}", ".ply", write)
            out_targets.append({"name": tname, "file": str(file), "weight": float(weights[j])})
        rec: dict[str, Any] = {"type": "morph-targets", "targets": out_targets}
        anim = self.motions.get(k, {}).get("weights")
        if anim:
            if len(anim) != len(targets):
                self.fail(where, f"the animation keys {len(anim)} morph weights for {len(targets)} targets")
            rec["animation"] = {"type": "keyframes", "time_unit": "seconds", "extrapolation": "hold", "channels": {tnames[j]: ch for j, ch in anim.items()}}
        return rec

    def _skin(self, k: int, n: Any, p: int, prim: Any, count: int, where: str, morph: dict[str, Any] | None) -> dict[str, Any]:
        skins = self.gltf.skins or []
        if not 0 <= n.skin < len(skins):
            self.fail(f"nodes[{k}].skin", f"skin {n.skin} does not exist")
        skin = skins[n.skin]
        swhere = f"skins[{n.skin}]" + (f" '{skin.name}'" if skin.name else "")
        joints = list(skin.joints or [])
        if not joints:
            self.fail(swhere, "has no joints")
        missing = [j for j in joints if j not in self.node_name]
        if missing:
            self.fail(f"{swhere}.joints", f"joint node {missing[0]} is not imported (outside the scene or the `nodes` selection)")
        attrs = prim.attributes
        if attrs.JOINTS_0 is None or attrs.WEIGHTS_0 is None:
            self.fail(f"{where}.attributes", "a skinned primitive needs JOINTS_0 and WEIGHTS_0")

        def write(tmp: Path) -> None:
            if skin.inverseBindMatrices is not None:
                ibm = self.accessor(skin.inverseBindMatrices, f"{swhere}.inverseBindMatrices")
                if ibm.shape != (len(joints), 16):
                    self.fail(f"{swhere}.inverseBindMatrices (accessor {skin.inverseBindMatrices})", f"{len(ibm)} matrices for {len(joints)} joints")
                ibm = ibm.reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major in the file
            else:
                ibm = np.broadcast_to(np.eye(4), (len(joints), 4, 4)).copy()
            sets = [(attrs.JOINTS_0, attrs.WEIGHTS_0)]
            if getattr(attrs, "JOINTS_1", None) is not None and getattr(attrs, "WEIGHTS_1", None) is not None:
                sets.append((attrs.JOINTS_1, attrs.WEIGHTS_1))
            idx_parts, w_parts = [], []
            for s, (ja, wa) in enumerate(sets):
                idx = self.accessor(ja, f"{where}.attributes.JOINTS_{s}")
                w = self.accessor(wa, f"{where}.attributes.WEIGHTS_{s}")
                if idx.shape != (count, 4) or w.shape != (count, 4):
                    self.fail(f"{where}.attributes.JOINTS_{s}", f"joints {idx.shape} / weights {w.shape} for {count} vertices; expected VEC4 each")
                if idx.min() < 0 or idx.max() >= len(joints):
                    self.fail(f"{where}.attributes.JOINTS_{s} (accessor {ja})", f"joint index {int(idx.max())} is out of range for {len(joints)} joints")
                idx_parts.append(idx)
                w_parts.append(w)
            idx, w = np.concatenate(idx_parts, axis=1), np.concatenate(w_parts, axis=1)
            if (w < 0).any():
                self.fail(f"{where}.attributes.WEIGHTS_0", "negative joint weight")
            total = w.sum(axis=1)
            if (total <= 0).any():
                v = int(np.flatnonzero(total <= 0)[0])
                self.fail(f"{where}.attributes.WEIGHTS_0 (accessor {attrs.WEIGHTS_0})", f"vertex {v} has no joint weight")
            # at most 4 influences (our linear blend skinning), renormalised
            order = np.argsort(-w, axis=1, kind="stable")[:, :4]
            idx, w = np.take_along_axis(idx, order, 1), np.take_along_axis(w, order, 1)
            w = w / w.sum(axis=1, keepdims=True)
            with open(tmp, "wb") as f:
                np.savez(f, inverse_bind=ibm, joint_indices=idx.astype(np.int32), joint_weights=w)

        file = cached(f"{self.path.stem}-skin{n.skin}-m{n.mesh}p{p}", f"{self.digest}|skin|{n.skin}|{n.mesh}|{p}", ".npz", write)
        rec: dict[str, Any] = {"type": "joint-skin", "joints": [self.node_name[j] for j in joints], "file": str(file)}
        if morph is not None:
            rec["morph"] = morph
        return rec

    # --- materials and textures ---------------------------------------------------------

    def _material_name(self, index: int | None) -> str:
        if index not in self.material_names:
            mats = self.gltf.materials or []
            if index is not None and not 0 <= index < len(mats):
                self.fail(f"materials[{index}]", "does not exist")
            base = (mats[index].name or f"material{index}") if index is not None else "gltf_default"
            self.material_names[index] = self.names.take(self.prefix + sanitize(base))
        return self.material_names[index]

    def _emission(self, index: int | None) -> dict[str, Any] | None:
        if index is None:
            return None
        mat = (self.gltf.materials or [])[index]
        factor = np.asarray(mat.emissiveFactor or [0, 0, 0], dtype=np.float64)
        strength = float(((mat.extensions or {}).get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0))
        if not factor.any() or strength <= 0:
            return None
        if mat.emissiveTexture is not None:
            # emissiveTexture x emissiveFactor x strength, in linear units: a float EXR
            # (a strength above 1 does not fit a PNG)
            where = f"materials[{index}].emissiveTexture"
            return {"radiance": self._texture(mat.emissiveTexture.index, where, scale=factor * strength, raw=False, linear=True)}
        return {"radiance": _floats(factor * strength)}

    def _material(self, index: int | None, name: str) -> dict[str, Any]:
        if index is None:  # the glTF default material: white, fully metallic and rough
            return {"name": name, "type": "principled", "color": 1.0, "metallic": 1.0, "roughness": 1.0}
        mat = self.gltf.materials[index]
        where = f"materials[{index}]" + (f" '{mat.name}'" if mat.name else "")
        self.at = where
        pbr = mat.pbrMetallicRoughness
        factor = list(pbr.baseColorFactor) if pbr is not None and pbr.baseColorFactor is not None else [1.0, 1.0, 1.0, 1.0]
        metallic = float(pbr.metallicFactor) if pbr is not None and pbr.metallicFactor is not None else 1.0
        roughness = float(pbr.roughnessFactor) if pbr is not None and pbr.roughnessFactor is not None else 1.0
        rec: dict[str, Any] = {"name": name, "type": "principled", "two_sided": bool(mat.doubleSided)}
        rgb = np.clip(np.asarray(factor[:3], dtype=np.float64), 0.0, None)
        if pbr is not None and pbr.baseColorTexture is not None:
            rec["color"] = self._texture(pbr.baseColorTexture.index, f"{where}.pbrMetallicRoughness.baseColorTexture", scale=rgb, raw=False)
        else:
            rec["color"] = _floats(rgb)
        if pbr is not None and pbr.metallicRoughnessTexture is not None:
            tw = f"{where}.pbrMetallicRoughness.metallicRoughnessTexture"
            # glTF packs roughness in G and metallic in B; each becomes its own grey texture
            rec["roughness"] = self._texture(pbr.metallicRoughnessTexture.index, tw, scale=np.array([roughness]), raw=True, channel=1)
            rec["metallic"] = self._texture(pbr.metallicRoughnessTexture.index, tw, scale=np.array([metallic]), raw=True, channel=2)
        else:
            rec["metallic"], rec["roughness"] = min(max(metallic, 0.0), 1.0), min(max(roughness, 0.0), 1.0)
        if mat.normalTexture is not None:  # tangent space, +Y up in the image as Mitsuba's normalmap reads it
            bend = float(mat.normalTexture.scale) if mat.normalTexture.scale is not None else 1.0
            rec["normal_map"] = self._texture(mat.normalTexture.index, f"{where}.normalTexture", scale=np.ones(1), raw=True, normal_scale=None if bend == 1.0 else bend)
        # alphaMode: OPAQUE ignores alpha; MASK cuts at alphaCutoff; BLEND is coverage
        mode = mat.alphaMode or "OPAQUE"
        if mode in ("MASK", "BLEND"):
            cutoff = float(mat.alphaCutoff if mat.alphaCutoff is not None else 0.5) if mode == "MASK" else None
            alpha = float(factor[3]) if len(factor) > 3 else 1.0
            if pbr is not None and pbr.baseColorTexture is not None:
                rec["opacity"] = self._texture(pbr.baseColorTexture.index, f"{where}.alphaMode", scale=np.array([alpha]), raw=True, channel=3, cutoff=cutoff)
            else:
                rec["opacity"] = (1.0 if alpha >= cutoff else 0.0) if cutoff is not None else min(max(alpha, 0.0), 1.0)
        return rec

    def _image_bytes(self, image: int, where: str) -> tuple[bytes, str]:
        images = self.gltf.images or []
        if not 0 <= image < len(images):
            self.fail(where, f"image {image} does not exist")
        img = images[image]
        iwhere = f"images[{image}]" + (f" '{img.uri}'" if img.uri and not img.uri.startswith("data:") else "")
        if img.bufferView is not None:
            data, start, length, _ = self._view(img.bufferView, iwhere)
            return data[start : start + length], iwhere
        if img.uri is None:
            self.fail(iwhere, "has neither uri nor bufferView")
        if img.uri.startswith("data:"):
            try:
                return base64.b64decode(img.uri.split(",", 1)[1], validate=True), iwhere
            except (ValueError, IndexError) as exc:
                self.fail(iwhere, f"bad data URI: {exc}")
        from urllib.parse import unquote

        file = self.path.parent / unquote(img.uri)
        if not file.exists():
            self.fail(iwhere, f"texture file not found (relative to {self.path.parent})")
        return self._read(file, MAX_IMAGE_BYTES, "texture file", iwhere), iwhere

    def _check_pixels(self, data: bytes, iwhere: str) -> None:
        """An image's size from its header, against the image bound (images.py), before a
        pixel is decoded: a 30000x30000 PNG header escaped as Pillow's DecompressionBombError."""
        import io

        from PIL import Image, UnidentifiedImageError

        from ...images import MAX_IMAGE_PIXELS

        try:
            with Image.open(io.BytesIO(data)) as im:
                width, height = im.size
        except Image.DecompressionBombError as exc:
            self.fail(iwhere, f"image over the limit of {MAX_IMAGE_PIXELS} pixels ({exc})")
        except (UnidentifiedImageError, OSError, ValueError) as exc:
            self.fail(iwhere, f"cannot decode the image: {exc}")
        if width * height > MAX_IMAGE_PIXELS:
            self.fail(iwhere, f"image of {width}x{height} pixels is over the limit of {MAX_IMAGE_PIXELS} pixels")

    def _texture(self, tex: int, where: str, scale: np.ndarray, raw: bool, channel: int | None = None, cutoff: float | None = None, linear: bool = False,
                 normal_scale: float | None = None) -> dict[str, Any]:
        """Texture `tex` in the asset cache as one of our texture records: the image x
        `scale` (colour in linear units), one `channel` of it (3: alpha) as grey, thresholded
        at `cutoff` (1 at or above, else 0), (`linear`) a float EXR of linear RGB, or a
        normal map with its x and y scaled by `normal_scale` (normalize((2c - 1) (s, s, 1)),
        as glTF's normalTexture.scale says)."""
        textures = self.gltf.textures or []
        if not 0 <= tex < len(textures):
            self.fail(where, f"texture {tex} does not exist")
        t = textures[tex]
        self.at = f"textures[{tex}]"
        if t.source is None:
            self.fail(f"textures[{tex}]", "has no image source")
        data, iwhere = self._image_bytes(t.source, f"textures[{tex}].source")
        self._check_pixels(data, iwhere)
        key = f"{bytes_digest(data)}|{_floats(scale)}|{channel}" + (f"|cut{cutoff}" if cutoff is not None else "") + ("|linear" if linear else "") + (f"|bend{normal_scale}" if normal_scale is not None else "")

        def write(tmp: Path) -> None:
            import io

            from PIL import Image, UnidentifiedImageError

            try:
                im = Image.open(io.BytesIO(data))
                im.load()
            except (UnidentifiedImageError, OSError) as exc:
                self.fail(iwhere, f"cannot decode the image: {exc}")
            if linear:
                import OpenEXR

                srgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255
                lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4) * scale
                OpenEXR.File({"type": OpenEXR.scanlineimage}, {"RGB": np.ascontiguousarray(lin, dtype=np.float32)}).write(str(tmp))
                return
            if normal_scale is not None:
                n = np.asarray(im.convert("RGB"), dtype=np.float64) / 255 * 2 - 1
                n[:, :, :2] *= normal_scale
                n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
                Image.fromarray(np.clip(np.rint((n + 1) / 2 * 255), 0, 255).astype(np.uint8)).save(tmp, format="PNG")
                return
            if channel is None and np.allclose(scale, 1.0):
                im.save(tmp, format="PNG")
                return
            arr = np.asarray(im.convert("RGBA" if channel == 3 else "RGB"), dtype=np.float64)
            if channel is not None:
                arr = arr[:, :, channel]
            factor = scale
            if cutoff is not None:
                arr = np.where(arr / 255 * scale[0] >= cutoff, 255.0, 0.0)
                factor = np.ones(1)
            # the factor multiplies the texture (in linear units for colour: decode sRGB first)
            if not raw:
                lin = np.where(arr / 255 <= 0.04045, arr / 255 / 12.92, ((arr / 255 + 0.055) / 1.055) ** 2.4) * factor
                arr = 255 * np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.clip(lin, 0, 1) ** (1 / 2.4) - 0.055)
            else:
                arr = arr * factor[0]
            Image.fromarray(np.clip(np.rint(arr), 0, 255).astype(np.uint8)).save(tmp, format="PNG")

        file = cached(f"{self.path.stem}-tex{tex}", key, ".exr" if linear else ".png", write)
        out: dict[str, Any] = {"file": str(file), "raw": raw}
        samplers = self.gltf.samplers or []
        if t.sampler is not None and 0 <= t.sampler < len(samplers):
            smp = samplers[t.sampler]
            if smp.wrapS in WRAP:
                out["wrap"] = WRAP[smp.wrapS]
            if smp.magFilter == 9728:
                out["filter"] = "nearest"
        return out

    # --- cameras and lights -------------------------------------------------------------

    def _camera(self, index: int, node: str) -> dict[str, Any]:
        cams = self.gltf.cameras or []
        if not 0 <= index < len(cams):
            self.fail(f"cameras[{index}]", "does not exist")
        cam = cams[index]
        self.at = f"cameras[{index}]"
        # glTF cameras look along -Z with +Y up; ours (Mitsuba's) along +Z: turn 180 about Y
        rec: dict[str, Any] = {"parent": node, "transform": {"rotate": {"axis": [0.0, 1.0, 0.0], "angle": 180.0}}}
        if cam.type == "orthographic" and cam.orthographic is not None:
            o = cam.orthographic
            rec.update({"type": "orthographic", "ortho_width": 2.0 * float(o.xmag), "near": float(o.znear), "far": float(o.zfar)})
        elif cam.perspective is not None:
            pcam = cam.perspective
            rec.update({"type": "perspective", "fov": math.degrees(float(pcam.yfov)), "fov_axis": "y", "near": float(pcam.znear)})
            if pcam.zfar is not None:
                rec["far"] = float(pcam.zfar)
        else:
            self.fail(f"cameras[{index}]", f"camera type '{cam.type}' without its parameters")
        return rec

    def _light(self, ext: dict[str, Any], node: str, where: str) -> dict[str, Any]:
        lights = ((self.gltf.extensions or {}).get("KHR_lights_punctual") or {}).get("lights") or []
        k = ext.get("light")
        if not isinstance(k, int) or not 0 <= k < len(lights):
            self.fail(f"{where}.extensions.KHR_lights_punctual", f"light {k} does not exist")
        light = lights[k]
        lwhere = f"KHR_lights_punctual.lights[{k}]"
        self.at = lwhere
        if not isinstance(light, dict):
            self.fail(lwhere, "a light is a JSON object")
        rgb = np.asarray(light.get("color", [1.0, 1.0, 1.0]), dtype=np.float64)
        power = rgb * float(light.get("intensity", 1.0)) * self.spec.light_scale
        if not np.isfinite(power).all() or (power < 0).any():
            self.fail(lwhere, "intensity and colour must be finite and non-negative")
        name = self.names.take(f"{node}.light")
        kind = light.get("type")
        rec: dict[str, Any] = {"name": name, "parent": node}
        if kind == "directional":
            rec.update({"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": _floats(power)})
        elif kind == "point":
            rec.update({"type": "point", "position": [0.0, 0.0, 0.0], "intensity": _floats(power)})
        elif kind == "spot":
            spot = light.get("spot") or {}
            outer = math.degrees(float(spot.get("outerConeAngle", math.pi / 4)))
            inner = math.degrees(float(spot.get("innerConeAngle", 0.0)))
            rec.update({"type": "spot", "position": [0.0, 0.0, 0.0], "look_at": [0.0, 0.0, -1.0], "intensity": _floats(power), "cutoff_angle": outer})
            if inner > 0:
                rec["beam_width"] = inner
        else:
            self.fail(f"{lwhere}.type", f"unknown light type '{kind}'")
        return rec


def source_digest(path: Path, raw: bytes) -> str:
    """sha256 over the glTF file's bytes as the reader read them (`raw`: a file swapped after
    it was read cannot give its converted assets another file's key) and the external files
    its buffers and images name (a .gltf's .bin and textures), so a converted asset is stale
    when any of them changes."""
    import hashlib
    import json
    from urllib.parse import unquote

    h = hashlib.sha256(bytes_digest(raw).encode())
    try:
        if raw[:4] == b"glTF":
            length = struct.unpack_from("<I", raw, 12)[0]
            doc = json.loads(raw[20 : 20 + length])
        else:
            doc = json.loads(raw.decode("utf-8"))
        uris = [item.get("uri") for key in ("buffers", "images") for item in doc.get(key) or [] if isinstance(item, dict)]
    except (ValueError, struct.error, AttributeError, TypeError, RecursionError):
        return h.hexdigest()  # the reader reports what is wrong with the file (JSON nested 100,000 deep, too)
    for uri in uris:
        if isinstance(uri, str) and not uri.startswith("data:"):
            file = path.parent / unquote(uri)
            h.update(f"|{uri}|".encode() + (file_digest(file).encode() if file.is_file() else b"missing"))
    return h.hexdigest()


def expand_gltf(path: Path, shown: str, spec: Any, index: int, raw: bytes | None = None) -> Expansion:
    """The records of one glTF import, read from the file, or parsed from `raw`, its bytes
    as memo.read_import hashed them for the key it keeps them by; ImportFileError (the file
    and node) or SpecError (the import entry's field) otherwise."""
    reader = None
    try:
        reader = GltfReader(path, shown, spec, index, raw)
        ex = reader.expand()
    except (SpecError, ImportFileError):
        raise
    except (TypeError, AttributeError, KeyError, IndexError, ValueError, OverflowError, struct.error) as exc:
        # a value of the wrong JSON type or shape that the checks above did not foresee:
        # still one located line (the item being read), never a traceback
        where = reader.at if reader is not None else "<file>"
        raise ImportFileError(shown, where, f"malformed glTF: {type(exc).__name__}: {exc}") from None
    return ex
