"""Helpers for the dynamics tests: small scenes written to a temporary directory."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from motion.pipeline.dynamics import simulate
from motion.pipeline.scene import load_scene


def ball(name: str, y: float, radius: float = 0.1, x: float = 0.0, z: float = 0.0, **motion: Any) -> dict[str, Any]:
    """A dynamics sphere at (x, y, z)."""
    return {"name": name, "shape": "sphere", "radius": radius, "transform": {"translate": [x, y, z]}, "motion": {"type": "dynamics", **motion}}


def floor(name: str = "floor", size: float = 100.0, y: float = 0.0, **collider: Any) -> dict[str, Any]:
    """A horizontal rectangle collider at height y (normal +Y)."""
    return {
        "name": name,
        "shape": "rectangle",
        "width": size,
        "height": size,
        "collider": {"restitution": 1.0, "friction": 0.3, **collider},
        "transform": {"translate": [0, y, 0], "rotate": {"euler": [-90, 0, 0]}},
    }


def dust_shot(name: str, last: int, dust_start: float, dust_stop: float) -> dict[str, Any]:
    """A small simulated shot from frame 1001: a ball dropped on a red floor and a burst of
    dust particles emitted from `dust_start` to `dust_stop` (s), tiny render settings."""
    return {
        "name": name,
        "timeline": {"fps": 24, "first": 1001, "last": last},
        "camera": {"position": [0, 1, 5], "look_at": [0, 0.5, 0], "fov": 40},
        "lights": [{"type": "constant", "radiance": 0.8}],
        "materials": [{"name": "red", "type": "diffuse", "color": [0.7, 0.1, 0.1]}],
        "objects": [
            {**floor(), "material": "red"},
            {**ball("ball", 1.0, radius=0.2, mass=2.0), "material": "red"},
            {"name": "dust", "shape": "particles", "radius": 0.02, "transform": {"translate": [0, 0.05, 0]},
             "emitter": {"rate": 400, "start": dust_start, "stop": dust_stop, "speed": 1.0, "spread": 30, "lifetime": 0.5, "seed": 3}},
        ],
        "render": {"resolution": [24, 16], "spp": 2, "max_depth": 2, "shutter_samples": 2},
    }


def write_scene(tmp_path: Path, objects: list[dict[str, Any]], dynamics: dict[str, Any] | None = None, name: str = "test", last: int = 24) -> Path:
    doc = {
        "name": name,
        "timeline": {"fps": 24, "first": 0, "last": last},
        "camera": {"position": [0, 1, 10], "look_at": [0, 0, 0]},
        "objects": objects,
        "dynamics": dynamics or {},
    }
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def run(tmp_path: Path, objects: list[dict[str, Any]], t_end: float, dynamics: dict[str, Any] | None = None, name: str = "test"):
    """Write, load and simulate a scene."""
    return simulate(load_scene(write_scene(tmp_path, objects, dynamics, name)), t_end)


def apexes(y: np.ndarray) -> np.ndarray:
    """Local maxima of a sampled height."""
    k = np.flatnonzero((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:])) + 1
    return y[k]
