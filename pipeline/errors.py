"""One base error for everything a user can cause; subclasses are named for the situation.

`motion.cli.main` catches `MotionError`, prints `str(err)` (one line per problem) and
exits with `err.exit_code`; no traceback reaches a user for these.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


class MotionError(Exception):
    """Base of every error caused by input, environment or configuration."""

    exit_code: int = 2


@dataclass(frozen=True)
class Problem:
    """One problem in one input file: where it is and what was expected."""

    file: str
    line: int | None
    column: int | None
    yaml_path: str
    message: str

    def __str__(self) -> str:
        where = self.file
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        path = self.yaml_path or "<document>"
        return f"{where}: {path}: {self.message}"


class SceneError(MotionError):
    """A scene (or preset, or baked-motion) file failed validation: every problem at once."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    @classmethod
    def single(
        cls,
        file: str | Path,
        yaml_path: str,
        message: str,
        line: int | None = None,
        column: int | None = None,
    ) -> "SceneError":
        """One located problem as an error (the common case outside schema validation)."""
        return cls([Problem(str(file), line, column, yaml_path, message)])


class UsageError(MotionError):
    """A command-line option is malformed (frame range, shard spec, preset name ...)."""


class AssetError(MotionError):
    """An asset file (mesh, texture, environment map) is missing or unreadable."""


class SceneChangedError(MotionError):
    """A worker loaded a scene (file, or its settings) other than the one the job was
    planned and baked from: the file was edited after `motion render` started (a late or
    respawned worker). Its frames would carry the old hashes and be trusted by --resume."""


class RendererError(MotionError):
    """The renderer could not be set up (no usable variant, Mitsuba failure)."""


class SimulationError(MotionError):
    """A dynamics simulation blew up or cannot proceed (names object, time, step)."""


class FrameIOError(MotionError):
    """An EXR frame is missing, truncated, unreadable or inconsistent with its sequence."""


class ReferenceMismatchError(MotionError):
    """`motion compare`: the new frames and the references were made from different
    scene versions or settings (the line names the difference), or cannot be compared
    pixel for pixel (resolution, frames); exit 2."""


class FramesDifferError(MotionError):
    """`motion compare`: some frames differ from their references beyond noise, or are
    missing (the line names the worst); exit 1, as a test run that failed."""

    exit_code = 1


class InputFileError(MotionError):
    """An input file (scene, preset, baked motion, asset) is not a regular file within the
    size limit, or cannot be read at all. Callers usually re-raise it as their own error."""

    def __init__(self, file: str, reason: str) -> None:
        self.file = file
        self.reason = reason
        super().__init__(f"{file}: {reason}")


class OutputConfinementError(MotionError):
    """A path the job would write (a frame, a claim) lies outside the output folder."""


class DiskFaultError(MotionError):
    """The disk refused a write (full, read-only, permission denied) while a job ran.

    The job stops at once: finished frames stay, no temporary or empty file and no claim
    of ours is left behind, no worker is blamed, and the report is written wherever it
    can be. Exit code 4 (docs/farm.md, "Disk faults")."""

    exit_code = 4


class IncompleteJobError(MotionError):
    """Some frames failed everywhere; the others finished. Exit code 3."""

    exit_code = 3


# Errors by stage. Each stage adds its own classes below its own heading (one owner per
# heading keeps parallel work free of merge conflicts); every class derives from one above.

# --- bake and render (data contract, renderer) ---


class BakeFileError(MotionError):
    """A baked-motion file cannot be written or read back (path, format, layout, values)."""


class FrameNotBakedError(MotionError):
    """A frame was asked of a bake that does not hold it."""


class FrameDataError(RendererError):
    """The per-frame poses given to the integrator do not have the shapes of its job
    (movers, lights or shutter samples other than those it was built for)."""


class SampleCountError(RendererError):
    """The film was asked for fewer than one sample per pixel."""


# --- dynamics and shape geometry ---


class ShapeGeometryError(MotionError):
    """A shape cannot give what a stage asked of it (a mesh, mass properties)."""


class UnknownShapeError(ShapeGeometryError):
    """A shape name with no entry in pipeline/geometry.py SHAPES."""


class ShapeNotTessellatedError(ShapeGeometryError):
    """A shape that has no tessellated mesh was asked for one (deformation, flocks)."""


class NotAMeshError(ShapeGeometryError):
    """Morph targets or a joint skin on an object that is not a mesh file."""


class GridTooLargeError(MotionError):
    """A planning occupancy grid (from an image or the scene) with more cells than allowed."""


class FlockTooLargeError(SimulationError):
    """A flock whose rendered vertices (agents x agent vertices) exceed the budget."""


class UnknownIntegratorError(SimulationError):
    """A dynamics integrator name that is not one of dynamics/integrators.py INTEGRATORS."""


class NoSuchTrackError(SimulationError):
    """A simulation was asked for a body group, particle system, flock or follower it did
    not simulate."""


# --- scene, expressions, motion, orchestration ---


class MeshFormatError(AssetError):
    """A mesh file is malformed: what is wrong and where (line or element). `load_mesh`
    reports it as an AssetError naming the file."""


class TrackError(MotionError, ValueError):
    """A keyframe channel's keys cannot be compiled; `loc` is the path below the channel.
    The motion stage reports it as a SceneError located at that key. Still a ValueError
    too, as it always was: a caller of the track compiler may catch it as one."""

    def __init__(self, loc: tuple[str | int, ...], message: str) -> None:
        super().__init__(message)
        self.loc = loc


class ExpressionValueError(MotionError):
    """A procedural expression or generator gave a value that cannot be used (not finite,
    a zero axis); `loc` is below the procedural block. Reported as a located SceneError."""

    def __init__(self, loc: tuple[str | int, ...], message: str) -> None:
        super().__init__(message)
        self.loc = loc


class RotationValueError(MotionError):
    """A rotation given as data cannot be made a unit quaternion: a zero quaternion, a zero
    axis, a value that is not Euler angles, turns on a segment with no axis. The keyframe
    and procedural stages report it located (TrackError, ExpressionValueError)."""


class ShotFolderTakenError(UsageError):
    """An output folder already holds the frames of another scene file (two scenes with
    the same `name:` share `out/<name>`): refused, naming both (shot/folder_owner.py)."""


class OutputInUseError(UsageError):
    """Another version of the scene (other settings or motion) is being rendered into the
    same output folder by a live run: rendering both would leave a mix of the two."""


# --- deliverables, telecine, examples ---
