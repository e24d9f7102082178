"""Scene stage: YAML -> validated, immutable records (docs/scene-format.md)."""

from .loader import LoadedScene, load_scene
from .schema import Scene

__all__ = ["LoadedScene", "Scene", "load_scene"]
