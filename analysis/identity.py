"""Names: method labels as the paper prints them, task display names, true action dimensions."""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Mapping
from typing import Any

from repro.config.schema import learner_specs, objective_specs

# agent.name (normalised: lower case, alphanumerics only) -> the paper's label, for the algorithms no registration
# names: the online learner without an objective (its registration, actor_critic, names the learner, not the agent
# file drqv2), and the baselines the paper quotes without runs here (DrQ, DreamerV3, TD-MPC)
UNREGISTERED_LABELS: dict[str, str] = {
    "drqv2": "DrQ-v2",
    "drq": "DrQ",
    "dreamerv3": "DreamerV3",
    "tdmpc": "TD-MPC",
}


@functools.cache
def agent_labels() -> dict[str, str]:
    """Normalised ``agent.name`` -> the paper's label: a learner's from its registration (its plain agent file is
    named after it; the built-in online learner's agent files are named after their objectives instead), an
    objective's (the online agent named after it: ``spr`` -> SPR), and :data:`UNREGISTERED_LABELS`. Plugins'
    learners and objectives included."""
    labels = dict(UNREGISTERED_LABELS)
    labels.update({agent_key(s.name): s.label for s in objective_specs().values() if s.label is not None})
    labels.update({agent_key(s.name): s.label for s in learner_specs().values()})
    return labels


# Names the paper prints that a plain title-casing would get wrong.
_TASK_NAMES: dict[str, str] = {
    "reach_duplo": "Reach Duplo",
    "manipulator_bring_ball": "Manipulator Bring Ball",
    "pick-place-wall": "Pick Place Wall",
    "stick-pull": "Stick Pull",
    "hand-insert": "Hand Insert",
}


def agent_key(name: Any) -> str:
    """Normalise an ``agent.name`` ("DrQ-v2", "drqv2", "td3_bc") to a lookup key ("drqv2", "td3bc")."""
    return re.sub(r"[^a-z0-9]", "", str(name).lower())


def enabled_objectives(objectives: Mapping[str, Any] | None) -> tuple[str, ...]:
    """Names of the auxiliary objectives with a non-zero weight, sorted."""
    if not objectives:
        return ()
    out = []
    for name, weight in objectives.items():
        try:
            on = float(weight) != 0.0
        except (TypeError, ValueError):
            on = bool(weight)
        if on:
            out.append(str(name))
    return tuple(sorted(out))


def agent_label(name: Any) -> str:
    """The label of an algorithm (``agent.name``, e.g. a bench result's agent file) from its name alone:
    :func:`agent_labels`, else the name. A run's label is :func:`method_label`, from what it trained."""
    return agent_labels().get(agent_key(name), str(name))


def objective_tags(objectives: Iterable[str]) -> list[str]:
    """The parts of a method label for the enabled ``objectives``, in registration order (names nobody registers
    here, a plugin's not installed: by name, last). An objective whose ``companions`` are all enabled names them
    too (TACO is the TACO, CURL and reward losses); with some of them off it says which (``TACO w/o CURL``)."""
    specs = objective_specs()
    on = set(map(str, objectives))
    absorbed = {c for name in on if name in specs for c in specs[name].companions if c in on}
    tags = []
    for name in [*(n for n in specs if n in on), *sorted(on - set(specs))]:
        spec = specs.get(name)
        if spec is None:
            tags.append(name)
        elif name not in absorbed:
            missing = [specs[c].tag for c in spec.companions if c not in on]
            tags.append(spec.tag + (f" w/o {', '.join(missing)}" if missing else ""))
    return tags


def method_label(learner: Any, objectives: Iterable[str] = ()) -> str:
    """A method's label, from the registry: the label of ``learner`` (``agent.learner``) then the label of each
    enabled objective (:func:`objective_tags`): ``CQL+TACO``, ``TD3+BC+SPR``. A learner registered with
    ``named_by_objectives`` (the online actor-critic) is named by its objectives alone when it has any: ``TACO``,
    ``SPR``, and ``DrQ-v2`` without. Two distinct (learner, enabled objectives) pairs never share a label
    (tests/test_plugins.py). A learner nobody registers here (a plugin's not installed) is named by its name."""
    spec = learner_specs().get(str(learner))
    tags = objective_tags(objectives)
    if spec is not None and spec.named_by_objectives and tags:
        return "+".join(tags)
    return "+".join([spec.label if spec is not None else str(learner), *tags])


def task_display(task: str) -> str:
    """The paper's name of a task: ``quadruped_run`` -> ``Quadruped Run``, ``stick-pull`` -> ``Stick Pull``."""
    if task in _TASK_NAMES:
        return _TASK_NAMES[task]
    return " ".join(part.capitalize() for part in re.split(r"[_\-]+", str(task)) if part)


def action_dim(task: str) -> int | None:
    """True action dimension of ``task`` (without distracting dimensions) from the task table, or None if unknown."""
    from repro.envs import TASKS  # cheap: a static table, no simulator import

    info = TASKS.get(str(task))
    return int(info.action_dim) if info is not None else None
