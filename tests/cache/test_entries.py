"""Cache entries: the import cache keeps to the asset cache's cap, and an entry damaged after
it was published is made again, not a hit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


def test_the_import_cache_keeps_to_the_asset_cache_cap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The import cache ignored MOTION_ASSET_CACHE_CAP (it grew without bound); it now
    evicts its least recently used entries like the converted-asset cache, never the entry
    just made."""
    from motion.pipeline.scene.imports import converted as cache

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("MOTION_ASSET_CACHE_CAP", "2500")
    made = [cache.cached(f"m{i}", f"key{i}", ".bin", lambda p: p.write_bytes(b"x" * 1000)) for i in range(5)]
    held = [p for p in made if p.exists()]
    assert made[-1] in held and sum(p.stat().st_size for p in held) <= 2500, held


def test_a_damaged_cache_entry_is_made_again_not_a_hit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An entry cut short or overwritten after it was published (a crash of another tool, a
    disk that lost it) was a hit in every later run, and every frame failed in Mitsuba's PLY
    reader (exit 3) until the cache was cleared by hand; both caches now check an entry on a
    hit as they do before publishing it, and make it again."""
    import numpy as np

    from motion.pipeline.meshes import load_mesh
    from motion.pipeline.render.translate.assets import mesh_file
    from motion.pipeline.scene.imports import converted as cache
    from motion.pipeline.variant import activate

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    activate("auto", quiet=True)  # mesh_file converts through Mitsuba (whatever variant this test process already set)
    src = tmp_path / "tri.obj"
    src.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    make = [lambda: mesh_file(src),
            lambda: cache.cached("tri", "key", ".ply", lambda p: cache.write_ply(p, pts, np.array([[0, 1, 2]])))]
    for entry in make:
        first = entry()
        whole = first.read_bytes()
        for damage in (whole[: len(whole) - 7], b"garbage\n"):
            first.write_bytes(damage)
            again = entry()
            assert again.read_bytes() == whole, damage
            assert len(load_mesh(again)[0]) == 3
