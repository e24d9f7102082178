"""What a shipped job carries: every file the scene names (scene/files.py's walk), each
once, by content hash and size; a file outside the scene's folder is refused before
anything is read or sent, and an import's converted files are renamed into the scene's
folder (`ship_imports`)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from ...errors import AssetError
from ...scene.files import NamedFile, file_digest, named_files, renamed
from ...scene.imports.converted import converted_file
from ...scene.schema import Scene
from ...scene.source import yaml_path


@dataclass(frozen=True)
class ShippedAsset:
    """One file a shipped job carries: its path relative to the scene's folder (as the
    scene names it), its SHA-256 content hash and its size in bytes."""

    rel: str
    sha256: str
    size: int


IMPORTED = ".motion-imports"  # where a shipped job's converted import files are named, in the scene's folder


def ship_imports(scene: Scene, base_dir: Path) -> tuple[Scene, dict[str, Path]]:
    """The scene with every file that import expansion made (a glTF or USD mesh converted
    into motion's own import cache, named there by an absolute path) renamed to
    `.motion-imports/<name>`, a path inside the scene's folder as a shipped job carries it;
    and where each renamed file lies on this machine. Those files are ours, converted from
    sources inside the scene's folder that the import stage opened and checked."""
    sources: dict[str, Path] = {}

    def carried(named: NamedFile) -> str | None:
        path = Path(base_dir) / named.rel
        if not converted_file(path):
            return None
        name = f"{IMPORTED}/{path.name}"
        sources[name] = path.resolve()
        return name

    return renamed(scene, carried), sources


def asset_manifest(scene: Scene, base_dir: Path, scene_file: str | Path, sources: dict[str, Path] | None = None) -> list[ShippedAsset]:
    """Every file the scene names (`named_files`, the asset checks' own walk), each once, by
    content hash. A path that leads outside the scene's folder (`..`, an absolute path, a
    link) raises AssetError naming the scene file and the YAML path, before any file is read:
    a shipped job never carries the client's other files to the cluster. `sources`: where
    the converted import files (`ship_imports`) lie."""
    base = Path(base_dir)
    sources = sources or {}
    named = list(named_files(scene))
    for f in named:
        if f.rel not in sources and not _inside(base, base / f.rel):
            raise AssetError(f"{scene_file}: {yaml_path(f.loc)}: {f.rel} lies outside the scene's folder {base.resolve()}; a shipped job sends only files inside it")
    out: dict[str, ShippedAsset] = {}
    for f in named:
        if f.rel not in out:
            path = sources.get(f.rel, base / f.rel)
            out[f.rel] = ShippedAsset(f.rel, file_digest(path), path.stat().st_size)  # hashed once per run: the settings hash read it too
    return list(out.values())


def _inside(base: Path, path: Path) -> bool:
    """Whether `path`, every link on it followed (its last part too: an asset that is a link
    to a file elsewhere is outside), lies inside `base`."""
    root, real = base.resolve(), path.resolve()
    return real == root or root in real.parents


def manifest_key(assets: Iterable[ShippedAsset]) -> str:
    """A short digest of a manifest (each file's scene-relative name and content hash)."""
    return hashlib.sha256("\n".join(sorted(f"{a.rel}\0{a.sha256}" for a in assets)).encode()).hexdigest()[:24]
