"""The scene-wide inputs of a frame's identity: the renderer's version, the render settings
as a frame's header keeps them, the files the scene names by their bytes, and the two
hashes a job carries (the scene file's bytes; the settings hash over the whole validated
scene with every override).

The settings hash is the scene's records walked as plain data (`bake.keep.plain`: each
model by its type and fields, floats exact) with every named file standing for its bytes
(`content_named`), `output.deliver` left out (what a full render assembles afterwards, not
how a frame looks), plus the renderer's version. It is what a worker checks the scene it
reads against, what the run lock and the cost history are keyed on, and what the kept
frame keys are found by (identity/kept.py).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Protocol

from ..bake.keep import plain
from ..scene.files import bytes_digest, named_files, readable_digests, renamed
from ..scene.schema import Scene

RENDERER_VERSION = "motion-render-1"


class Located(Protocol):
    """A parsed scene and its folder (scene/loader.py's `LoadedScene`)."""

    @property
    def scene(self) -> Scene:
        """The validated scene."""
        ...

    @property
    def base_dir(self) -> Path:
        """The folder its relative file names start from."""
        ...


def render_settings(scene: Any) -> dict[str, Any]:
    """The settings a frame is rendered with (the scene's `render:` block as resolved from
    flag, preset, scene and default, and how it is stored), kept in each frame's header so
    a rerun can name the setting that makes an existing frame stale."""
    out = scene.output
    return {**scene.render.model_dump(mode="json"), "pixel_type": out.pixel_type, "compression": out.compression, "aovs": list(out.aovs)}


def named_digests(scene: Scene, base_dir: Path) -> dict[str, str | None]:
    """Each file the scene names (by its name in the scene) -> the digest of its bytes, or
    None when it cannot be read; each file read once."""
    out: dict[str, str | None] = {}
    for named in named_files(scene):
        if named.rel not in out:
            out[named.rel] = readable_digests([Path(base_dir) / named.rel])[0]
    return out


def content_named(loaded: Located) -> Scene:
    """The scene with every file it names (meshes, textures, environment maps, an import's
    converted files) given as `sha256:<digest of its bytes>`: a frame's settings hash then
    changes when a texture is edited under the same name (`--resume` replaces the frames,
    a warm worker does not serve the old scene), and does not depend on where the file
    lies (an import's converted meshes sit in each machine's own cache folder: a worker
    under another user computed another hash and refused the job). A file that cannot be
    read stands as `unreadable:<name>` (the asset checks report it before any task)."""
    digests = named_digests(loaded.scene, loaded.base_dir)
    return renamed(loaded.scene, lambda f: f"sha256:{digests[f.rel]}" if digests[f.rel] else f"unreadable:{f.rel}")


def file_digests(loaded: Located) -> dict[str, str]:
    """The files the scene names -> the first 16 hex digits of each one's digest, as kept
    in a frame's header (`motion:files`) so that a rerun can name the file that changed.
    An import's converted file is named `import:<its name>` (its path lies in this
    machine's cache folder, which does not belong in a deliverable)."""
    from ..scene.imports.converted import converted_file

    out = {}
    for rel, digest in named_digests(loaded.scene, loaded.base_dir).items():
        path = loaded.base_dir / rel
        out[f"import:{path.name}" if converted_file(path) else rel] = digest[:16] if digest else "unreadable"
    return out


def settings_digest(loaded: Located) -> str:
    """The full SHA-256 (hex) the settings hash is the first 16 digits of: the renderer's
    version and the content-named scene as plain data, without `output.deliver`."""
    canon = plain(content_named(loaded))
    output = canon.get("output")
    if isinstance(output, dict):
        output.pop("deliver", None)
    text = json.dumps(canon, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(f"{RENDERER_VERSION}|{text}".encode()).hexdigest()


def scene_file_hash(loaded: Any) -> str:
    """The scene hash: 16 hex digits of the digest of the scene file's bytes."""
    return bytes_digest(loaded.path.read_bytes())[:16]


def scene_hashes(loaded: Any) -> tuple[str, str]:
    """(scene, settings) hashes, 16 hex digits each: the scene file's bytes; the validated
    scene with every override applied, each file it names standing for its contents, plus
    the renderer's version (`settings_digest`)."""
    return scene_file_hash(loaded), settings_digest(loaded)[:16]
