"""Registry of auxiliary objectives; importing this package registers the built-in ones."""

from repro.agent.objectives import atc as _atc  # noqa: F401  (registers atc)
from repro.agent.objectives import driml as _driml  # noqa: F401  (registers driml)
from repro.agent.objectives import spr as _spr  # noqa: F401  (registers spr)
from repro.agent.objectives import taco as _taco  # noqa: F401  (registers taco, curl, reward)
from repro.agent.objectives.base import OBJECTIVES, AuxBatch, Objective, ObjectiveContext, register
from repro.config.schema import ObjectiveName, check_registry

check_registry("objective", OBJECTIVES, ObjectiveName)  # the names agent.objectives may use are schema data

__all__ = ["OBJECTIVES", "AuxBatch", "Objective", "ObjectiveContext", "register"]
