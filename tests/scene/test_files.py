"""The files a scene names and the digest of a file's bytes have one home, scene/files.py:
no other module of pipeline/ or cli/ hashes a file's bytes itself, and the walk, the
renaming and the digests agree on a real scene (every kind of named file the examples use)."""

from __future__ import annotations

import ast
import hashlib
from pathlib import Path

from motion.pipeline.scene import load_scene
from motion.pipeline.identity.inputs import content_named, file_digests, named_digests
from motion.pipeline.scene.files import (
    CHUNK,
    bytes_digest,
    digests_recorded,
    file_digest,
    named_files,
    readable_digests,
    renamed,
    snapshot,
)

ROOT = Path(__file__).resolve().parents[2]
HOME = ROOT / "pipeline" / "scene" / "files.py"


def _hashes_file_bytes(tree: ast.AST) -> list[int]:
    """Lines that hash a file's bytes by hand: a hashlib constructor given `.read_bytes()`,
    or a chunked read loop `iter(lambda: f.read(n), b"")`."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        fn = node.func
        if isinstance(fn, ast.Attribute) and isinstance(fn.value, ast.Name) and fn.value.id == "hashlib":
            if any(isinstance(a, ast.Call) and isinstance(a.func, ast.Attribute) and a.func.attr == "read_bytes" for arg in node.args for a in ast.walk(arg)):
                found.append(node.lineno)
        if isinstance(fn, ast.Name) and fn.id == "iter" and node.args and isinstance(node.args[0], ast.Lambda):
            body = node.args[0].body
            if isinstance(body, ast.Call) and isinstance(body.func, ast.Attribute) and body.func.attr == "read":
                found.append(node.lineno)
    return found


def test_one_digest_of_a_files_bytes() -> None:
    """Only scene/files.py reads a file to hash it (one algorithm, one chunk size)."""
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for folder in ("pipeline", "cli")
        for path in sorted((ROOT / folder).rglob("*.py"))
        if path != HOME
        for line in _hashes_file_bytes(ast.parse(path.read_text()))
    ]
    assert not found, found
    assert _hashes_file_bytes(ast.parse(HOME.read_text())), "the check sees the home's own loop"


def test_digests_agree(tmp_path: Path) -> None:
    """`file_digest` (kept or afresh), `bytes_digest`, `readable_digests` and `snapshot`
    give SHA-256 of the same bytes, across the chunk boundary; a reader's files are recorded."""
    data = bytes(range(256)) * (CHUNK // 256 * 2 + 3)
    path = tmp_path / "big.bin"
    path.write_bytes(data)
    want = hashlib.sha256(data).hexdigest()
    with digests_recorded() as read:
        assert file_digest(path) == want
    assert read == {str(path.resolve()): want}
    assert file_digest(path, memo=False) == bytes_digest(data) == want
    assert readable_digests([path, tmp_path / "missing"]) == [want, None]
    with snapshot(path, len(data), "test file") as (digest, copy):
        assert digest == want and copy.read_bytes() == data and copy != path


def test_walk_rename_and_digests_on_a_scene() -> None:
    """On the example scenes: every named file is listed with its YAML location,
    `renamed` replaces exactly those fields, `content_named` names each by its bytes and
    `file_digests` records the same digests."""
    seen_kinds: set[str] = set()
    for scene_file in sorted((ROOT / "scenes").glob("*.yaml")):
        loaded = load_scene(scene_file, assets=False)
        named = list(named_files(loaded.scene))
        if not named:
            continue
        seen_kinds |= {f.kind for f in named}
        digests = named_digests(loaded.scene, loaded.base_dir)
        assert list(digests) == list(dict.fromkeys(f.rel for f in named))
        for rel, digest in digests.items():
            assert digest == hashlib.sha256((loaded.base_dir / rel).read_bytes()).hexdigest()
        marked = renamed(loaded.scene, lambda f: f"<{f.kind}>")
        assert [f.rel for f in named_files(marked)] == [f"<{f.kind}>" for f in named]
        by_content = list(named_files(content_named(loaded)))
        assert [f.loc for f in by_content] == [f.loc for f in named]
        assert [f.rel for f in by_content] == [f"sha256:{digests[f.rel]}" for f in named]
        header = file_digests(loaded)
        assert all(header[rel] == digest[:16] for rel, digest in digests.items() if rel in header)
    assert {"mesh", "image"} <= seen_kinds, seen_kinds
