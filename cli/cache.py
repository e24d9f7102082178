"""`motion cache info|clear|key|warm`: the shared on-disk caches (converted assets, drjit
kernels, what validation keeps); `key` and `warm` serve a CI system that saves the kernel
cache between runs (docs/ci-sharding.md)."""

from __future__ import annotations

from pathlib import Path

import click


def _folders() -> dict[str, Path]:
    from motion.pipeline.cache import STORES, kernels_dir, validation_dir
    from motion.pipeline.render.translate.assets import assets_dir

    return {"assets": assets_dir(), "kernels": kernels_dir(), "validation": validation_dir(), "shipped": STORES["shipped"].dir(),
            "simulations": STORES["simulations"].dir()}


@click.group("cache")
def cache() -> None:
    """Inspect or clear motion's on-disk caches (shared by all workers on this machine)."""


@cache.command("info")
def cache_info() -> None:
    """Entries, bytes, hits and misses of each cache (one line per store of pipeline/cache.py),
    then drjit's kernel cache."""
    from motion.pipeline.cache import STORES, kernels_dir, trusted_folder
    from motion.pipeline.cache import kernel_files as drjit_files

    for store in STORES.values():
        files, size = store.info()
        ours = "" if not store.dir().is_dir() or trusted_folder(store.dir()) else "  (writable by others: its entries are not used)"
        click.echo(f"{store.name:<15} {files:>6} files {size / 1e6:>10.1f} MB  {store.dir()}{ours}")
    kernels = drjit_files()
    size = 0
    for path in kernels:
        try:
            size += path.stat().st_size
        except OSError:
            continue  # swept or replaced while we looked
    click.echo(f"{'kernels':<15} {len(kernels):>6} files {size / 1e6:>10.1f} MB  {kernels_dir()}")


@cache.command("clear")
@click.option("--what", type=click.Choice(["all", "assets", "kernels", "validation", "shipped", "simulations"]), default="all", show_default=True)
def cache_clear(what: str) -> None:
    """Delete cached files (they are rebuilt on demand): assets holds the converted assets,
    imports and import records; validation the kept validators, parsed scene files and asset passes; shipped
    what shipped jobs carried to this worker; simulations the kept dynamics simulations."""
    from motion.pipeline.cache import clear_kernels
    from motion.pipeline.render.translate.assets import clear

    for name, folder in _folders().items():
        if what in ("all", name):
            # the kernel folder may be $DRJIT_CACHE_DIR, shared with others: only drjit's files go
            removed = clear_kernels(folder) if name == "kernels" else clear(folder)
            click.echo(f"{name}: removed {removed} files from {folder}")


@cache.command("key")
def cache_key() -> None:
    """A key for saving and restoring the kernel cache in CI: it changes when compiled
    kernels could no longer be reused (Mitsuba, drjit, motion, Python, CPU). Prints the key,
    then the folder to save (DRJIT_CACHE_DIR)."""
    from motion.pipeline.cache import kernel_cache_key, kernels_dir

    click.echo(kernel_cache_key())
    click.echo(str(kernels_dir()))


@cache.command("warm")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--preset", help="The preset the CI job renders with (its resolution, depth and frames make its kernels).")
@click.option("--frames", "frames_spec", metavar="SPEC", help="The frames the job renders (its --frames); default: the preset's frames when it names a count, else the first frame.")
def cache_warm(scene: Path, preset: str | None, frames_spec: str | None) -> None:
    """Compile SCENE's kernels into the kernel cache by rendering the frames the CI job
    renders (into a temporary folder, then removed), so its first frame is a warm one."""
    import logging
    import tempfile

    from motion.pipeline.cache import kernels_dir
    from motion.pipeline.presets import load_preset
    from motion.pipeline.scene import load_scene
    from motion.pipeline.shot import RenderRequest, run_render

    before = kernel_files(kernels_dir())
    frames: tuple[int, ...] | None = None
    if not frames_spec and not (preset and load_preset(preset)[0].frame_count):
        frames = (load_scene(scene).scene.timeline.first,)  # a whole shot's frames would be the job itself
    log = logging.getLogger("motion")
    level = log.level
    with tempfile.TemporaryDirectory(prefix="motion-warm-") as tmp:
        log.setLevel(max(level, logging.WARNING))  # the render's lines name files in a folder removed at once
        try:
            rep = run_render(RenderRequest(scene=scene, output_dir=Path(tmp), frames=frames, frames_spec=frames_spec, preset=preset,
                                           deliver="none", progress=False, report=Path(tmp) / "report.json"))
        finally:
            log.setLevel(level)
    rows = rep.get("frames", [])
    compiled = sum(int(r.get("kernels_compiled") or 0) for r in rows)
    done = ",".join(str(r["frame"]) for r in rows)
    after = kernel_files(kernels_dir())
    click.echo(f"kernels: {compiled} compiled for {scene} (frames {done}); {len(after)} kernel files ({len(after - before):+d}) in {kernels_dir()}")


def kernel_files(folder: Path) -> set[str]:
    """The names of drjit's kernel files in `folder` (`*.bin` as drjit names them: not its
    `sweep.stamp` nor a writer's `*.tmp`, which come and go beside them, nor anyone else's)."""
    from motion.pipeline.cache import kernel_files as drjit_files

    return {p.name for p in drjit_files(folder) if p.name.endswith(".bin")}


commands = [cache]
