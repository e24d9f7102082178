"""The kept simulation: a run whose dynamics inputs did not change reads the simulation an
earlier run made from the cache layer (`cache.STORES["simulations"]`) instead of simulating
again (docs/bake-format.md, "The kept simulation").

- The key (`simulation_key`) is what the simulation depends on, and only that: the scene's
  timeline, objects (without their material and emission: how a thing looks does not move
  it), dynamics settings and IK constraints as validated records, with every file the
  objects name given by the digest of its bytes; the simulated time range; the code of the
  stages the simulation runs (dynamics/, motion/ and what they read below them); numpy's and
  scipy's versions. A comment, the scene's name, a material, a light, the camera, the render
  and output settings change nothing.
- An entry is plain data: one uncompressed `.npz` of numpy arrays (read with
  `allow_pickle=False`) and a JSON outline of the records they fill, whose classes come from
  a fixed table (`_HOMES`); nothing in it is executed. Each member carries the zip format's
  CRC-32, checked as it is read; a damaged or forged entry (unreadable, a CRC that does not
  match, a record or array of the wrong kind, sampling that fails) is one warning, discarded
  and simulated again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Callable

from ..cache import STORES, Store, trusted

if TYPE_CHECKING:
    import numpy as np

    from ..scene.loader import LoadedScene

log = logging.getLogger("motion")

STORE: Store = STORES["simulations"]
FORMAT = "motion-simulation/1"
_OUTLINE = "__outline__"  # the JSON outline, as uint8
# what the simulation's code is: the stages it runs and the modules they read below them
CODE_FOLDERS = ("dynamics", "motion")
CODE_FILES = ("bake/keep.py", "bake/timing.py", "geometry.py", "meshes.py", "expr.py", "timeline.py", "scene/dynamics_schema.py",
               "scene/motion_schema.py", "scene/schema.py", "scene/types.py")
_LOOK_ONLY = ("material", "emission")  # object fields the simulation never reads
_code_version: str | None = None


# the records an entry may hold, by name -> their module (imported only when an entry holds
# one: a flock's module imports scipy.spatial, 0.4 s)
_HOMES = {
    "Simulation": "motion.pipeline.dynamics.simulation",
    "ParticleSystem": "motion.pipeline.dynamics.simulation",
    "Track": "motion.pipeline.dynamics.track",
    "Spawns": "motion.pipeline.dynamics.particles",
    "FlockTrack": "motion.pipeline.dynamics.flock",
    "FollowerTrack": "motion.pipeline.dynamics.follower",
}


def _record_class(name: str) -> type | None:
    """The record class an outline names, from `_HOMES` only; None for any other name."""
    import importlib

    home = _HOMES.get(name)
    return None if home is None else getattr(importlib.import_module(home), name)


def code_version() -> str:
    """The digest of the simulation's code (`CODE_FOLDERS`' modules and `CODE_FILES`) and
    of the numeric libraries' versions; read once a process."""
    global _code_version
    if _code_version is None:
        import numpy as np

        from importlib.metadata import PackageNotFoundError, version

        from ..cache import code_digest

        source = Path(__file__).resolve().parents[1]
        files = sorted(str(p.relative_to(source)) for folder in CODE_FOLDERS for p in (source / folder).glob("*.py"))
        try:
            scipy = version("scipy")
        except PackageNotFoundError:
            scipy = "?"
        _code_version = code_digest(files + list(CODE_FILES)) + f"|numpy={np.__version__}|scipy={scipy}"
    return _code_version


def plain(value: Any, depth: int = 0) -> Any:
    """A validated record as JSON data: each model as its type and fields (walked here:
    pydantic's own `model_dump` builds its serializers first, 0.25 s a process)."""
    from fractions import Fraction

    from pydantic import BaseModel

    np = sys.modules.get("numpy")  # no array can be here before numpy is imported (a rerun that bakes nothing)
    fields: dict[type, tuple[str, ...]] = {}

    def walk(value: Any, depth: int) -> Any:  # (the imports above made once, not at every node: a 2,000-object scene has 54,000)
        if depth > 64:
            raise ValueError("the scene's records nest deeper than 64 levels")
        if value is None or isinstance(value, (bool, int, str)):
            return value
        if isinstance(value, float):
            return {"float": value.hex()}
        if isinstance(value, BaseModel):
            cls = type(value)
            names = fields.get(cls)
            if names is None:
                names = fields[cls] = tuple(cls.model_fields)
            return {"type": cls.__name__, **{k: walk(getattr(value, k), depth + 1) for k in names}}
        if isinstance(value, (list, tuple)):
            return [walk(v, depth + 1) for v in value]
        if isinstance(value, dict):
            return {str(k): walk(v, depth + 1) for k, v in value.items()}
        if isinstance(value, Fraction):
            return {"fraction": str(value)}
        if np is not None and isinstance(value, np.ndarray):  # exact: a long array's repr elides its middle
            data = np.ascontiguousarray(value)
            return {"array": [data.dtype.str, list(data.shape), hashlib.sha256(data.tobytes()).hexdigest()]}
        return {type(value).__name__: repr(value)}

    return walk(value, depth)


def dynamics_inputs(loaded: "LoadedScene") -> dict[str, Any]:
    """The validated records the simulation reads, as plain JSON data: timeline, objects
    (without `_LOOK_ONLY` fields; the files they name as `sha256:<digest>`), dynamics and
    IK."""
    from ..scene.files import named_files, readable_digests, renamed

    def moves(loc: Any) -> bool:
        return loc[0] == "objects" and "emission" not in loc

    digests: dict[str, str] = {}
    for named in named_files(loaded.scene):
        if moves(named.loc) and named.rel not in digests:
            digest = readable_digests([loaded.base_dir / named.rel])[0]
            digests[named.rel] = f"sha256:{digest}" if digest else f"unreadable:{named.rel}"
    scene = renamed(loaded.scene, lambda f: digests.get(f.rel) if moves(f.loc) else None) if digests else loaded.scene
    objects = [{k: v for k, v in plain(o).items() if k not in _LOOK_ONLY} for o in scene.objects]
    return {"timeline": plain(scene.timeline), "objects": objects, "dynamics": plain(scene.dynamics), "ik": plain(scene.ik)}


def simulation_key(loaded: "LoadedScene", t_start: float, t_end: float) -> str:
    """The key of the simulation of `loaded` over [t_start, t_end] (`dynamics_inputs`, the
    range as exact floats, `code_version`)."""
    inputs = json.dumps(dynamics_inputs(loaded), sort_keys=True, separators=(",", ":"))
    return STORE.key(FORMAT, code_version(), hashlib.sha256(inputs.encode()).hexdigest(), float(t_start).hex(), float(t_end).hex())


# --- plain data: records <-> outline + arrays -----------------------------------------------------


def _outline(value: Any, arrays: dict[str, np.ndarray]) -> Any:
    """`value` as JSON data, its arrays moved to `arrays` (named a0, a1, ...)."""
    import numpy as np

    if isinstance(value, np.ndarray):
        name = f"a{len(arrays)}"
        arrays[name] = np.ascontiguousarray(value)
        return {"array": name}
    if isinstance(value, np.generic):
        return _outline(value.item(), arrays)
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return {"float": value.hex()}
    if isinstance(value, (list, tuple)):
        return {"list" if isinstance(value, list) else "tuple": [_outline(v, arrays) for v in value]}
    if isinstance(value, dict):
        return {"dict": [[str(k), _outline(v, arrays)] for k, v in value.items()]}
    if dataclasses.is_dataclass(value) and _HOMES.get(type(value).__name__) == type(value).__module__:
        return {"record": type(value).__name__, "fields": {f.name: _outline(getattr(value, f.name), arrays) for f in dataclasses.fields(value)}}
    raise TypeError(f"the simulation holds a {type(value).__name__}, which a kept simulation cannot carry")


class DamagedEntry(Exception):
    """A kept simulation that cannot be believed (why: the message)."""


def _rebuild(node: Any, arrays: Any, depth: int = 0) -> Any:
    """The value an outline node stands for; DamagedEntry for anything not of the format."""
    if depth > 16:
        raise DamagedEntry("nested too deep")
    if node is None or isinstance(node, (bool, int, str)):
        return node
    if not isinstance(node, dict) or len(node) not in (1, 2):
        raise DamagedEntry("an outline node of no known kind")
    if "array" in node:
        if node["array"] not in arrays.files:
            raise DamagedEntry(f"array {node['array']!r} is missing")
        return arrays[node["array"]]
    if "float" in node:
        return float.fromhex(str(node["float"]))
    if "list" in node or "tuple" in node:
        items = [_rebuild(v, arrays, depth + 1) for v in node.get("list", node.get("tuple")) or []]
        return items if "list" in node else tuple(items)
    if "dict" in node:
        return {str(k): _rebuild(v, arrays, depth + 1) for k, v in node["dict"]}
    cls = _record_class(str(node.get("record")))
    fields = node.get("fields")
    if cls is None or not isinstance(fields, dict) or set(fields) != {f.name for f in dataclasses.fields(cls)}:
        raise DamagedEntry(f"a record {node.get('record')!r} of no known kind or fields")
    return cls(**{k: _rebuild(v, arrays, depth + 1) for k, v in fields.items()})


def encode(simulation: Any) -> bytes:
    """The simulation as one uncompressed .npz: its arrays and its outline (each member
    carries the zip format's CRC-32 of its bytes, checked as it is read back)."""
    import numpy as np

    arrays: dict[str, np.ndarray] = {}
    outline = json.dumps({"format": FORMAT, "value": _outline(simulation, arrays)}, separators=(",", ":")).encode()
    buf = io.BytesIO()
    np.savez(buf, **arrays, **{_OUTLINE: np.frombuffer(outline, dtype=np.uint8)})
    return buf.getvalue()


def _read_npy(member: BinaryIO, size: int) -> np.ndarray:
    """One .npy member, its header believed only as far as its own bytes go: a numeric dtype,
    and a shape whose bytes fit in the member's `size` (a forged shape allocates nothing)."""
    import numpy as np

    fmt = np.lib.format
    version = fmt.read_magic(member)
    shape, fortran, dtype = (fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0)(member)
    if dtype.hasobject or dtype.kind not in "biuf":
        raise DamagedEntry("an array of no numeric type")
    count = 1
    for n in shape:
        count *= int(n)
    nbytes = count * dtype.itemsize
    if nbytes > size:
        raise DamagedEntry(f"an array of {nbytes} bytes in a member of {size}")
    data = bytearray(nbytes)
    if member.readinto(data) != nbytes:
        raise DamagedEntry("an array cut short")
    if member.read(1):  # the member ends with its array; reading to its end checks its CRC-32
        raise DamagedEntry("bytes after an array")
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")


def decode(data: bytes | BinaryIO, limit: int) -> Any:
    """The simulation an entry (its bytes, or the open file) holds; DamagedEntry when it is
    not one (bounded: at most `limit` bytes once unpacked, stored members only, no pickles; a
    damaged byte fails its member's CRC-32 as it is read)."""
    import numpy as np

    source = io.BytesIO(data) if isinstance(data, bytes) else data
    try:
        import zipfile  # (here: a rerun that reads no kept simulation never loads it)

        with zipfile.ZipFile(source) as z:
            infos = z.infolist()
            if any(i.compress_type != zipfile.ZIP_STORED for i in infos) or sum(i.file_size for i in infos) > limit:
                raise DamagedEntry("compressed or larger than its bound")
            arrays = {}
            for info in infos:
                if not info.filename.endswith(".npy"):
                    raise DamagedEntry(f"a member {info.filename[:40]!r} that is no array")
                with z.open(info) as member:
                    arrays[info.filename[:-4]] = _read_npy(member, info.file_size)
    except DamagedEntry:
        raise
    except Exception as exc:  # a damaged zip or .npy header: any of zipfile's, numpy's or the OS's errors
        raise DamagedEntry(f"unreadable ({type(exc).__name__})") from None
    outline_arr = arrays.pop(_OUTLINE, None)
    if outline_arr is None or outline_arr.dtype != np.uint8:
        raise DamagedEntry("no outline")
    outline = outline_arr.tobytes()
    if any(a.dtype.kind not in "biuf" for a in arrays.values()):
        raise DamagedEntry("an array of no numeric type")
    try:
        doc = json.loads(outline)
    except ValueError:
        raise DamagedEntry("its outline is not JSON") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise DamagedEntry("another format")

    class _Arrays:
        files = set(arrays)

        def __getitem__(self, name: str) -> np.ndarray:
            return arrays[name]

    try:
        simulation = _rebuild(doc.get("value"), _Arrays())
    except DamagedEntry:
        raise
    except Exception as exc:  # a record that its own constructor refuses
        raise DamagedEntry(f"a record that cannot be made ({type(exc).__name__})") from None
    if not isinstance(simulation, _record_class("Simulation")):
        raise DamagedEntry("it holds no simulation")
    return simulation


def _samples(simulation: Any) -> None:
    """Sample every track the simulation holds at its ends (a kept entry must answer what a
    bake asks of it); raises what a malformed track raises."""
    import numpy as np

    times = np.array([simulation.t_start, (simulation.t_start + simulation.t_end) / 2, simulation.t_end], dtype=np.float64)
    simulation.sample(times)
    for name in simulation.particle_systems:
        simulation.particles(name, times)
    for name in list(simulation.flocks):
        simulation.flock(name).at(times)
    for name in list(simulation.followers):
        simulation.follower(name).at(times)
    simulation.energy()
    simulation.body_energy()


MAX_KEPT_BYTES = 4 << 30  # one kept simulation, unpacked


def kept(loaded: "LoadedScene", t_start: float, t_end: float, simulate: Callable[[], Any]) -> Any:
    """The simulation of `loaded` over [t_start, t_end]: the kept one when there is one,
    else `simulate()`, kept for the next run (best effort: a full disk costs only the next
    run's simulation). Logs which."""
    import numpy as np

    key = simulation_key(loaded, t_start, t_end)
    entry = STORE.path(key, stem="sim", suffix=".npz")
    st = trusted(entry)  # ours, a regular file (never a FIFO), in folders only we may write
    if st is None and os.path.lexists(entry):
        STORE.stats["refused"] += 1
    if st is not None and st.st_size <= MAX_KEPT_BYTES:
        try:
            with open(entry, "rb") as f:  # read in place: a 100 MB entry is not copied into memory first
                simulation = decode(f, MAX_KEPT_BYTES)
            with np.errstate(all="ignore"):
                _samples(simulation)
        except DamagedEntry as exc:
            log.warning(f"motion: warning: the kept simulation {entry} is damaged ({exc}): discarded, simulating again")
            STORE.stats["refused"] += 1
        except Exception as exc:  # a forged track that sampling refuses
            log.warning(f"motion: warning: the kept simulation {entry} is damaged ({type(exc).__name__} when sampled): discarded, simulating again")
            STORE.stats["refused"] += 1
        else:
            STORE.stats["hits"] += 1
            try:
                entry.touch()  # least recently used order
            except OSError:
                pass
            log.info(f"motion: bake: the simulation of {t_start:.4g}-{t_end:.4g} s is kept from an earlier run (not simulated again)")
            return simulation
    STORE.stats["misses"] += 1
    simulation = simulate()
    try:
        data = encode(simulation)
    except TypeError as exc:  # a record the format does not know: simulated, just not kept
        log.debug(f"motion: the simulation is not kept: {exc}")
        return simulation
    if len(data) <= MAX_KEPT_BYTES:
        STORE.put(entry, data, best_effort=True, doing="keeping the simulation")
    return simulation
