"""Registry of auxiliary objectives; importing this package registers the built-in ones and the plugins' (the names
are registered in repro/config/schema.py, ``objective_specs``: a plugin's names its class by ``factory``)."""

from repro.agent.objectives import atc as _atc  # noqa: F401  (registers atc)
from repro.agent.objectives import driml as _driml  # noqa: F401  (registers driml)
from repro.agent.objectives import spr as _spr  # noqa: F401  (registers spr)
from repro.agent.objectives import taco as _taco  # noqa: F401  (registers taco, curl, reward)
from repro.agent.objectives.base import OBJECTIVES, AuxBatch, Objective, ObjectiveContext, register
from repro.config.plugins import load_factory
from repro.config.schema import check_registry, objective_names, objective_specs

for _spec in objective_specs().values():
    if _spec.factory is not None:  # a plugin's objective: its class, under its registered name
        _cls = load_factory(_spec)
        if not (isinstance(_cls, type) and issubclass(_cls, Objective)):
            raise TypeError(f"objective '{_spec.name}': {_spec.factory} is not an Objective subclass")
        register(_spec.name)(_cls)
check_registry("objective", OBJECTIVES, objective_names())  # every registered objective has its code

__all__ = ["OBJECTIVES", "AuxBatch", "Objective", "ObjectiveContext", "register"]
