"""Auxiliary objectives by name: the table is built from the registrations (repro/config/schema.py
``objective_specs``: the built-in ones and the entry-point group ``taco_repro.objectives``), each naming its class by
``factory``, imported here. A built-in objective is registered exactly as a plugin's."""

from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext
from repro.config.plugins import ObjectiveSpec, PluginError, load_factory
from repro.config.schema import objective_specs


def _objective_class(spec: ObjectiveSpec) -> type[Objective]:
    """The class ``spec.factory`` names, an :class:`Objective` subclass, named ``spec.name`` (its metric columns)."""
    cls = load_factory(spec)
    if not (isinstance(cls, type) and issubclass(cls, Objective)):
        raise PluginError(f"objective '{spec.name}': {spec.factory} is not an Objective subclass")
    cls.name = spec.name
    return cls


OBJECTIVES: dict[str, type[Objective]] = {spec.name: _objective_class(spec) for spec in objective_specs().values()}

__all__ = ["OBJECTIVES", "AuxBatch", "Objective", "ObjectiveContext"]
