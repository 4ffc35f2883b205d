"""Names: method labels as the paper prints them, task display names, true action dimensions."""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from typing import Any

from repro.config.schema import is_offline, learner_specs, objective_specs

# agent.name (normalised: lower case, alphanumerics only) -> the paper's label, for the algorithms no registration
# names: the online learner without an objective, and the baselines whose published curves the paper compares to
UNREGISTERED_LABELS: dict[str, str] = {
    "drqv2": "DrQ-v2",
    "alix": "A-LIX",
    "drq": "DrQ",
    "dreamerv3": "DreamerV3",
    "tdmpc": "TD-MPC",
}


@functools.cache
def algo_labels() -> dict[str, str]:
    """Normalised ``agent.name`` -> the paper's label: a learner's from its registration (its plain agent file is
    named after it; the built-in online learner's agent files are named after their objectives instead), an
    objective's (the online agent named after it: ``spr`` -> SPR), and :data:`UNREGISTERED_LABELS`. Plugins'
    learners and objectives included."""
    labels = dict(UNREGISTERED_LABELS)
    labels.update({algo_key(s.name): s.label for s in objective_specs().values() if s.label is not None})
    labels.update({algo_key(s.name): s.label for s in learner_specs().values()})
    return labels


@functools.cache
def offline_learners() -> frozenset[str]:
    """The offline learners' names, normalised (agent.name of their plain agent files), from the registry."""
    return frozenset(algo_key(n) for n in learner_specs() if is_offline(n))


# Names the paper prints that a plain title-casing would get wrong.
_TASK_NAMES: dict[str, str] = {
    "reach_duplo": "Reach Duplo",
    "manipulator_bring_ball": "Manipulator Bring Ball",
    "pick-place-wall": "Pick Place Wall",
    "stick-pull": "Stick Pull",
    "hand-insert": "Hand Insert",
}


def algo_key(name: Any) -> str:
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


def method_label(name: Any, objectives: tuple[str, ...] = ()) -> str:
    """The paper's label of a method: ``TACO``, ``DrQ-v2``, ``CQL+TACO`` (an offline learner with TACO).

    ``name``: an online run's algorithm (``agent.name``) or an offline run's learner (``agent.learner``: ``cql``
    for the ``cql_taco`` agent)."""
    key = algo_key(name)
    label = algo_labels().get(key, str(name))
    if key in offline_learners() and "taco" in objectives:
        label += "+TACO"
    return label


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
