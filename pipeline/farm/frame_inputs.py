"""Where the farm's per-frame motion comes from: baked here (`bake()`, once, in the main
process, before any worker starts) or read from a file written by `motion bake`
(`--motion FILE`, through `bake.read_baked`). Either way the result is a list of
`BakedFrame`s, the records the workers render."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from ..bake import BakedFrame, BakedMotion, evaluate_frames, read_baked, simulate_for
from ..errors import BakeFileError, UsageError
from ..scene.loader import LoadedScene


def simulation_for(loaded: LoadedScene, frames: Sequence[int], on_progress: Any = None) -> Any:
    """Simulate once (before sharding), if the scene has dynamics, over the range bake
    owns (`bake.simulation_range`: the whole timeline, not the selection), so every shard
    and every frame range bakes the same motion for the same frame."""
    if not frames:
        return None
    return simulate_for(loaded, frames, on_progress=on_progress)


def baked_inputs(loaded: LoadedScene, frames: Sequence[int], simulation: Any = None) -> Sequence[BakedFrame]:
    """Bake `frames` here (poses, vertices, particles); [] for no frames."""
    return evaluate_frames(loaded, frames, simulation)


def _check_meta(baked: BakedMotion, loaded: LoadedScene, path: Path) -> None:
    """The file was baked from this scene with this render's frame rate, shutter and
    shutter samples; UsageError naming every difference."""
    scene = loaded.scene
    problems = []
    if baked.scene != loaded.name:
        problems.append(f"baked from scene {baked.scene!r}, rendering {loaded.name!r}")
    if baked.fps != str(scene.timeline.rate):
        problems.append(f"fps {baked.fps} differs from the scene's {scene.timeline.rate}")
    if baked.frames and baked.samples_per_frame != scene.render.shutter_samples:
        problems.append(f"{baked.samples_per_frame} shutter samples per frame, the render needs {scene.render.shutter_samples} (render.shutter_samples)")
    if baked.shutter_angle != float(scene.camera.shutter.angle) or baked.shutter_position != scene.camera.shutter.position:
        problems.append(f"shutter {{'angle': {baked.shutter_angle}, 'position': {baked.shutter_position!r}}} differs from the scene's camera shutter")
    if problems:
        raise UsageError(f"--motion {path}: " + "; ".join(problems))


def file_inputs(loaded: LoadedScene, path: str | Path, frames: Sequence[int]) -> list[BakedFrame]:
    """`frames` from a `motion bake` file (.json or .npz), checked against the scene."""
    from .selection import format_frames

    path = Path(path)
    nonrigid = [o.name for o in loaded.scene.objects if o.is_nonrigid]
    if nonrigid and path.suffix.lower() != ".npz":
        # JSON carries rigid poses only (docs/bake-format.md)
        raise UsageError(
            f"--motion {path}: {loaded.name} has particle systems or deforming meshes ({', '.join(nonrigid)}), "
            "whose geometry a JSON bake does not carry; bake to .npz (motion bake SCENE -o motion.npz)"
        )
    try:
        baked = read_baked(path, half=loaded.scene.output.pixel_type == "half", frames=frames)
    except BakeFileError as exc:
        raise BakeFileError(f"--motion {exc}") from None
    _check_meta(baked, loaded, path)
    if nonrigid and baked.frames:
        first = baked.frames[0].at_frame
        lacking = [n for n in nonrigid if n not in first.vertices and n not in first.particles]
        if lacking:
            raise UsageError(
                f"--motion {path}: it has no frame-time geometry for {', '.join(lacking)} "
                "(an NPZ from before the bake carried it); bake it again with this version"
            )
    by_frame = {f.frame: f for f in baked.frames}
    missing = [f for f in frames if f not in by_frame]
    if missing:
        raise UsageError(f"--motion {path}: frames {format_frames(missing)} are not in the baked file")
    return [by_frame[f] for f in frames]
