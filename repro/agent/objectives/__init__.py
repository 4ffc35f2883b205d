"""Registry of auxiliary objectives; importing this package registers the built-in ones."""

from repro.agent.objectives.base import OBJECTIVES, AuxBatch, Objective, ObjectiveContext, register
from repro.agent.objectives import taco as _taco  # noqa: F401  (registers taco, curl, reward)

__all__ = ["OBJECTIVES", "AuxBatch", "Objective", "ObjectiveContext", "register"]
