"""Registrations of learners and auxiliary objectives, and their discovery through entry points.

A learner or an objective is registered by one :class:`LearnerSpec` / :class:`ObjectiveSpec`: the built-in ones in
``repro/config/schema.py`` (``BUILTIN_LEARNERS``, ``BUILTIN_OBJECTIVES``), a package outside this tree through the
entry-point groups :data:`LEARNER_GROUP` and :data:`OBJECTIVE_GROUP` (its pyproject.toml's
``[project.entry-points."taco_repro.learners"]``: ``NAME = "its_module:ITS_SPEC"``). A spec is data: its module
must stay light (no torch), since the config loads it to validate names; the code it names by ``factory`` is
imported only by the layer that builds it (``repro.learners.registry``, ``repro.agent.objectives``).
docs/extending.md walks through one of each.
"""

from __future__ import annotations

import re
from dataclasses import MISSING, dataclass, fields, is_dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import TypeVar

from repro.config.bounds import A_NAME, Bound, Text, check_declarations
from repro.config.errors import UserError

__all__ = ["A_NAME", "Bound", "LEARNER_GROUP", "LearnerSpec", "OBJECTIVE_GROUP", "ObjectiveSpec", "PluginError", "Text",
           "check_spec", "discover", "load_factory"]

LEARNER_GROUP = "taco_repro.learners"
OBJECTIVE_GROUP = "taco_repro.objectives"
NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")


class PluginError(UserError, ValueError):
    """A registration that cannot be used, in one line."""


@dataclass(frozen=True)
class LearnerSpec:
    """What the tool needs to treat a learner as first-class.

    ``name`` is the ``agent.learner`` value (the registry key). ``offline``: it trains from ``offline.dataset``
    (else in an environment, as the online actor-critic). ``label``: the paper-style method label of its runs in
    tables and figures. ``section``: its typed settings, a dataclass whose values are the ``agent.<name>`` section
    of its agent files (read by it alone: other learners' runs neither hold nor check it). ``factory``: the learner
    class (or a callable with its signature, ``repro.learners.registry.LearnerFactory``) as ``"module:attribute"``
    (the built-in learners' too: ``repro/learners/registry.py`` builds its table from the registrations).
    ``conf``: a folder holding ``agent/<agent>.yaml`` files that use it (added to Hydra's search path, so
    ``agent=<agent>`` composes).
    A field of ``section`` declares its allowed values in its annotation (``temperature: Annotated[float,
    Bound(gt=0.0)]``: :mod:`repro.config.bounds`), checked with every other field's (one line, exit 2, before a run
    writes anything).
    ``named_by_objectives``: its label names its runs without objectives only; a run with objectives is named by
    their labels alone (the built-in online actor-critic: the paper's TACO, SPR, CURL are DrQ-v2 with objectives);
    otherwise a run's label is the learner's label, then its objectives' (``analysis.identity.method_label``).
    ``resolve``: a function ``(cfg: DictConfig) -> None`` as ``"module:attribute"`` (light: the config layer calls
    it) that fills what the learner resolves from its run's config once it is validated, in place, before anything
    is written (CQL's alpha from the paper's Table 6 when ``agent.cql.alpha`` is null); ValueError (one line) for a
    config it cannot resolve. So no generic module names a learner.
    """

    name: str
    offline: bool
    label: str
    section: type | None = None
    factory: str | None = None
    conf: str | Path | None = None
    named_by_objectives: bool = False
    resolve: str | None = None


@dataclass(frozen=True)
class ObjectiveSpec:
    """An auxiliary objective: ``name`` is its key in ``agent.objectives``; ``label`` its part of a method's label
    (``taco`` -> ``TACO``, ``CQL+TACO``; None: the name); ``factory``, ``conf``: as :class:`LearnerSpec` (the class
    is an ``repro.agent.objectives.base.Objective``).
    ``companions``: registered objectives that the method named ``label`` trains with it (the paper's TACO is the
    TACO, CURL and reward losses): with all of them enabled, ``label`` alone names the lot; with some off, the label
    says which (``TACO w/o CURL``).
    ``params``: its parameters, a dataclass whose fields (each with a default: the objective's own) are the settings
    ``agent.objective_params.<name>.<setting>``. A run's values are checked against it (a misspelled setting, a value
    of the wrong type, an integer given as a float: one line, exit 2, before a run writes anything) and the objective
    reads them as an instance of it (``ObjectiveContext.params``). None: it takes no parameters (any given is refused).
    A field declares its allowed values in its annotation, as a learner's ``section`` does (``hidden_dim:
    Annotated[Optional[int], Bound(ge=1)] = None``), checked in the runs whose ``agent.objectives`` names it."""

    name: str
    label: str | None = None
    factory: str | None = None
    conf: str | Path | None = None
    companions: tuple[str, ...] = ()
    params: type | None = None

    @property
    def tag(self) -> str:
        """Its part of a method label: ``label``, or the name when it registers none."""
        return self.label or self.name


Spec = TypeVar("Spec", LearnerSpec, ObjectiveSpec)


def check_spec(spec: LearnerSpec | ObjectiveSpec, where: str) -> None:
    """Raise PluginError (one line) when a registration cannot be used: a bad name, no factory, a missing conf."""
    if not NAME_RE.match(spec.name):
        raise PluginError(f"{where}: name '{spec.name}' must be lower-case letters, digits and '_'.")
    if spec.factory is None or ":" not in spec.factory:
        raise PluginError(f"{where}: factory must be 'module:attribute' (got {spec.factory!r}).")
    if isinstance(spec, LearnerSpec) and spec.resolve is not None and ":" not in spec.resolve:
        raise PluginError(f"{where}: resolve must be 'module:attribute' (got {spec.resolve!r}).")
    if spec.conf is not None and not (Path(spec.conf) / "agent").is_dir():
        raise PluginError(f"{where}: conf folder {spec.conf} has no agent/ folder.")
    if isinstance(spec, LearnerSpec) and spec.section is not None and not (
            isinstance(spec.section, type) and is_dataclass(spec.section)):
        raise PluginError(f"{where}: section must be a dataclass (got {spec.section!r}).")
    if isinstance(spec, ObjectiveSpec) and spec.params is not None:
        if not (isinstance(spec.params, type) and is_dataclass(spec.params)):
            raise PluginError(f"{where}: params must be a dataclass (got {spec.params!r}).")
        no_default = [f.name for f in fields(spec.params) if f.default is MISSING and f.default_factory is MISSING]
        if no_default:
            raise PluginError(f"{where}: params {spec.params.__name__} must give every field a default (the "
                              f"objective's own; missing for {', '.join(no_default)}).")
    typed = spec.section if isinstance(spec, LearnerSpec) else spec.params
    problem = check_declarations(typed) if typed is not None else None
    if typed is not None and problem is not None:
        raise PluginError(f"{where}: {'section' if isinstance(spec, LearnerSpec) else 'params'} {typed.__name__}: "
                          f"{problem}")


def discover(group: str, kind: type[Spec]) -> tuple[Spec, ...]:
    """The registrations of the installed packages in the entry-point ``group``, sorted by name; PluginError (one
    line) for one that does not load, is not a ``kind`` or is registered under another name than its own."""
    out: list[Spec] = []
    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        where = f"entry point '{ep.name}' of {group} ({ep.value})"
        try:
            spec = ep.load()
        except Exception as exc:  # a plugin's import error, whatever it is, is one line naming the plugin
            raise PluginError(f"{where}: cannot load: {type(exc).__name__}: {exc}") from None
        if not isinstance(spec, kind):
            raise PluginError(f"{where}: is a {type(spec).__name__}, not a {kind.__name__}.")
        if spec.name != ep.name:
            raise PluginError(f"{where}: registers '{spec.name}' under the entry-point name '{ep.name}'.")
        check_spec(spec, where)
        out.append(spec)
    return tuple(out)


def load_factory(spec: LearnerSpec | ObjectiveSpec, attribute: str = "factory") -> object:
    """The object a registration's ``factory`` (or its ``resolve``) names, imported by ``pkgutil.resolve_name``;
    PluginError (one line) when it fails. Called by the layer that builds it (``repro.learners.registry``,
    ``repro.agent.objectives``; ``resolve``: the config); a plugin's modules are outside this project, so
    tests/test_layers.py's one-way rule does not apply to them."""
    import pkgutil

    target = getattr(spec, attribute)
    assert isinstance(target, str)
    try:
        return pkgutil.resolve_name(target)
    except (ImportError, AttributeError, ValueError) as exc:
        raise PluginError(f"'{spec.name}': cannot import its {attribute} {target}: {type(exc).__name__}: {exc}") \
            from None
