"""The files a scene names, and the digest of a file's bytes: one home for both.

- The walk: `named_files(scene)` gives every file the scene names (meshes, blend-shape
  keys, skins, morph targets, a plan's grid image, light images, emission and material
  textures) with its YAML location, kind and whether it deforms; `replace_at` sets the
  field at such a location; `renamed` gives the scene with some of its files named anew.
  What the asset checks open (scene/checks.py), what a shipped job carries
  (farm/transfer/manifest.py), what a frame's identity reads (identity/inputs.py:
  `content_named`, `file_digests`) all come from this one walk: a new kind of named
  file is one more `yield` here.
- The digest: SHA-256 read in 1 MiB chunks (`ALGORITHM`, `CHUNK`). `file_digest` (kept per
  path, size and modification time: the key of every content-addressed cache), `bytes_digest`
  for bytes already in memory, `snapshot` for a private copy of exactly the bytes hashed,
  `digests_recorded` for the files a reader hashed.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Callable, Iterator, NamedTuple, Sequence

from .motion_schema import BlendShapes, JointSkin, MorphTargets
from .schema import Mesh, Scene, Texture

if TYPE_CHECKING:
    from .source import Loc

ALGORITHM = "sha256"  # every digest of a file's bytes
CHUNK = 1 << 20  # bytes read at a time

_DIGESTS: dict[tuple[str, int, int], str] = {}
_RECORDERS: list[dict[str, str]] = []  # open `digests_recorded` blocks, innermost last


# --- the digest of a file's bytes -----------------------------------------------------------------


def _hash_stream(src: IO[bytes], sink: Callable[[bytes], object] | None = None) -> str:
    """The digest of everything `src` still holds, read a chunk at a time; each chunk also
    goes to `sink` (a copy being written, a size bound) when given."""
    h = hashlib.new(ALGORITHM)
    for chunk in iter(lambda: src.read(CHUNK), b""):
        if sink is not None:
            sink(chunk)
        h.update(chunk)
    return h.hexdigest()


def bytes_digest(data: bytes) -> str:
    """The digest of bytes already in memory (a shipped file as received, an embedded
    image), equal to `file_digest` of a file holding them."""
    return hashlib.new(ALGORITHM, data).hexdigest()


def file_digest(path: Path, memo: bool = True) -> str:
    """SHA-256 of a file's bytes: the key of every content-addressed cache (imports,
    validation, shipped assets) and of the settings hash. Kept per path, size and
    modification time (a file is read once a process); `memo=False` reads it afresh (a check
    that the file did not change meanwhile) and leaves the kept digests alone. OSError when it
    cannot be read."""
    if not memo:
        with open(path, "rb") as f:
            return _hash_stream(f)
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _DIGESTS:
        with open(path, "rb") as f:
            _DIGESTS[key] = _hash_stream(f)
    for seen in _RECORDERS:
        seen[key[0]] = _DIGESTS[key]
    return _DIGESTS[key]


def readable_digests(paths: Sequence[str | Path]) -> list[str | None]:
    """Each file's digest (`file_digest`), or None where this process cannot read it (run on
    a Dask worker by farm/transfer/choose.py's `workers_see`)."""
    out: list[str | None] = []
    for path in paths:
        try:
            out.append(file_digest(Path(path)))
        except OSError:
            out.append(None)
    return out


@contextmanager
def snapshot(path: Path, limit: int, what: str) -> Iterator[tuple[str, Path]]:
    """`with snapshot(path, limit, what) as (digest, copy):` the digest of `path`'s bytes
    and a private copy of exactly those bytes (same file name, in a folder only we can
    reach, removed on leaving), for a check or a conversion whose result is kept by that
    digest: what is checked is what was hashed, whatever becomes of `path` meanwhile. The
    file is opened as every input is (`limits.open_bounded`: a FIFO is never waited on);
    InputFileError otherwise."""
    from ..limits import InputFileError, open_bounded

    folder = Path(tempfile.mkdtemp(prefix="motion-snapshot-"))
    try:
        copy = folder / Path(path).name
        size = 0
        with open_bounded(path, limit, what) as src, open(copy, "wb") as dst:

            def keep(chunk: bytes) -> None:
                nonlocal size
                size += len(chunk)
                if size > limit:
                    raise InputFileError(str(path), f"{what} is over the limit of {limit} bytes")
                dst.write(chunk)

            digest = _hash_stream(src, keep)
        yield digest, copy
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def digests_recorded() -> Iterator[dict[str, str]]:
    """Every file `file_digest` reads inside the block, by resolved path, with its digest:
    the inputs of a reader whose output is kept (a USD stage's layers and the textures it
    converts; a glTF file's buffers and images: imports/memo.py)."""
    seen: dict[str, str] = {}
    _RECORDERS.append(seen)
    try:
        yield seen
    finally:
        del _RECORDERS[next(i for i, r in enumerate(_RECORDERS) if r is seen)]


# --- the files a scene names ----------------------------------------------------------------------


class NamedFile(NamedTuple):
    """One file the scene names: its YAML location, its path as the scene gives it (relative
    to the scene's folder), its kind ('mesh', 'image', 'morph': a morph target's vertices,
    'skin': a joint skin's arrays) and whether it is a mesh that deforms."""

    loc: "Loc"
    rel: str
    kind: str
    deforming: bool = False


def named_files(scene: Scene) -> Iterator[NamedFile]:
    """Every file the scene names, in file order: what the asset checks open, what a farm
    that ships its inputs sends and what a frame's settings hash reads."""
    for i, obj in enumerate(scene.objects):
        if isinstance(obj, Mesh):
            yield NamedFile(("objects", i, "file"), obj.file, "mesh", obj.deform is not None)
        if isinstance(obj.deform, BlendShapes):
            for k, key in enumerate(obj.deform.keys):
                if key.file is not None:
                    yield NamedFile(("objects", i, "deform", "keys", k, "file"), key.file, "mesh")
        if isinstance(obj.deform, JointSkin):
            yield NamedFile(("objects", i, "deform", "file"), obj.deform.file, "skin")
        morph = obj.deform if isinstance(obj.deform, MorphTargets) else getattr(obj.deform, "morph", None)
        if isinstance(morph, MorphTargets):
            at = ("objects", i, "deform") if morph is obj.deform else ("objects", i, "deform", "morph")
            for k, target in enumerate(morph.targets):
                yield NamedFile((*at, "targets", k, "file"), target.file, "morph")
        if obj.motion.type == "plan" and obj.motion.grid.image is not None:
            yield NamedFile(("objects", i, "motion", "grid", "image"), obj.motion.grid.image, "image")
    for i, light in enumerate(scene.lights):
        for name in light.image_files:
            yield NamedFile(("lights", i, name), getattr(light, name), "image")
    for i, obj in enumerate(scene.objects):
        if obj.emission is not None and isinstance(obj.emission.radiance, Texture):
            yield NamedFile(("objects", i, "emission", "radiance", "file"), obj.emission.radiance.file, "image")
    for i, mat in enumerate(scene.materials):
        for name in type(mat).model_fields:
            tex = getattr(mat, name, None)
            if isinstance(tex, Texture):
                yield NamedFile(("materials", i, name, "file"), tex.file, "image")


def replace_at(model: Any, loc: Sequence[Any], value: Any) -> Any:
    """`model` (a frozen scene record) with the field at YAML path `loc` (as `named_files`
    gives it) set to `value`."""
    head, rest = loc[0], loc[1:]
    if not rest:
        return model.model_copy(update={head: value})
    child = getattr(model, head)
    if isinstance(child, (list, tuple)):
        items = list(child)
        items[rest[0]] = replace_at(items[rest[0]], rest[1:], value) if rest[1:] else value
        return model.model_copy(update={head: type(child)(items)})
    return model.model_copy(update={head: replace_at(child, rest, value)})


def renamed(scene: Scene, new_name: Callable[[NamedFile], str | None]) -> Scene:
    """The scene with each file it names given `new_name(file)` instead (None: kept as it is)."""
    for named in list(named_files(scene)):
        name = new_name(named)
        if name is not None:
            scene = replace_at(scene, named.loc, name)
    return scene
