"""Motion stage: evaluate every object's, the camera's and the lights' pose at any times
(keyframes, procedural generators and expressions, parent frames, deformation).

Contract (docs/architecture.md): `evaluate(loaded, times, simulation=None) -> SceneMotion`.
"""

from ..expr import ExpressionError, parse_expression
from .evaluate import SceneMotion, SimulationRequiredError, evaluate, has_dynamics
from .pose import Pose

__all__ = [
    "ExpressionError",
    "Pose",
    "SceneMotion",
    "SimulationRequiredError",
    "evaluate",
    "has_dynamics",
    "parse_expression",
]
