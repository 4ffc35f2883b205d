"""Format versions of a run directory's ``config.yaml`` and ``meta.json``, and the migrations between them.

Every reader of these two files goes through :func:`migrate_config` / :func:`migrate_meta`, so a run written by an
older version loads, resumes, extends and is analysed as if written today. Each version step is one function of
:data:`CONFIG_STEPS` / :data:`META_STEPS`; a change of either file's structure adds a step (and its test in
tests/test_budgets.py), never a rule elsewhere.

Versions:
- config 1: no ``format`` key, every learner's section (written before issue 24). Files of this version may lack
  keys that were added while it was current: they behaved as :data:`V1_OLD_BEHAVIOUR` says for the learners
  listed there, and as the value in ``data/config_v2_defaults.yaml`` (the packaged defaults when version 2 began)
  otherwise.
- config 2: ``format: 2``; only the keys the run's learner reads (``repro.config.compose.prune_unread``).
- config 3: ``format: 3``; ``agent.fast`` (issue 26; runs written before it ran the plain path: ``false``). The
  packaged defaults when version 3 began are ``data/config_v3_defaults.yaml``.
- config 4: ``format: 4``; each learner's own section (``agent.cql``, ``agent.td3bc``, ``agent.iql``, ``agent.dt``) is
  composed by its own agent files only, no longer a field of every run's agent config (issue 35). A file of
  version 2 or 3 already held only its learner's section (``prune_unread``): the step renumbers it. The packaged
  defaults when version 4 began are ``data/config_v4_defaults.yaml``.
- meta 1: no ``format`` key, no ``budgets``.
- meta 2: ``format: 2``; ``budgets`` (each budget the run reached: ``budget``, ``finished``) and ``extensions``
  (``from``, ``to``, ``time``); ``migrations`` lists the files migrated on disk (``file``, ``from``, ``to``, ``time``).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from repro.config.compose import ABSENT, get_key, pop_key, prune_unread, set_key
from repro.config.errors import UserError
from repro.config.schema import LearnerName

CONFIG_FORMAT = 4  # the version config.yaml is written in
META_FORMAT = 2  # the version meta.json is written in
V2_DEFAULTS = Path(__file__).resolve().parent / "data" / "config_v2_defaults.yaml"
CURRENT_DEFAULTS = Path(__file__).resolve().parent / "data" / f"config_v{CONFIG_FORMAT}_defaults.yaml"
FREE_MAPPINGS = ("agent.objectives", "agent.objective_params")  # names chosen per agent file, not fields

_L = LearnerName
# Keys added (while config format 1 was current) together with a change of behaviour: a run of these learners
# written before the key existed behaved as the value here, not as the new default (issue 16).
V1_OLD_BEHAVIOUR: dict[str, tuple[tuple[LearnerName, ...], object]] = {
    "agent.stddev_schedule.step_scale": ((_L.td3bc, _L.cql, _L.iql), 1),
    "agent.cql.clip_policy_samples": ((_L.cql,), False),
    # no value of today's switch: the old order (actor before, critic after the value step) is gone
    "agent.iql.value_for_targets": ((_L.iql,), "actor before, critic after the value step"),
    "agent.dt.activation": ((_L.dt,), "gelu"),
    "agent.dt.init": ((_L.dt,), "torch"),
    "agent.dt.ff_dropout": ((_L.dt,), True),
    "agent.dt.action_pad": ((_L.dt,), 0.0),
}


class FormatError(UserError, ValueError):
    """A file of a format version this code does not know (one line)."""


@dataclass(frozen=True)
class Diff:
    """One structural difference between two configs: the dotted ``path`` and both values (:data:`ABSENT` when
    one side lacks the key)."""

    path: str
    old: Any
    new: Any

    def __str__(self) -> str:
        return f"{self.path}: {self.old!r} -> {self.new!r}"


def diff(old: Any, new: Any, prefix: str = "") -> list[Diff]:
    """Every leaf where ``old`` and ``new`` (nested dicts) differ, sorted by path."""
    if isinstance(old, dict) and isinstance(new, dict):
        out: list[Diff] = []
        for key in sorted(set(old) | set(new), key=str):
            out.extend(diff(old.get(key, ABSENT), new.get(key, ABSENT), f"{prefix}{key}."))
        return out
    return [] if old == new else [Diff(prefix[:-1], old, new)]


# ------------------------------------------------------------------------------------------------ config.yaml
def _frozen(path: Path) -> dict:
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


@cache
def v2_defaults() -> dict:
    """The packaged defaults when config format 2 began (agent taco, task cheetah_run), as plain containers."""
    return _frozen(V2_DEFAULTS)


@cache
def current_defaults() -> dict:
    """The packaged defaults when the current config format began (agent taco, task cheetah_run): today's keys
    must be exactly these (tests/test_budgets.py), or a new format version and its step are due."""
    return _frozen(CURRENT_DEFAULTS)


def _leaves(data: dict, prefix: str = "") -> list[str]:
    out: list[str] = []
    for key, value in data.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict) and value and path not in FREE_MAPPINGS:
            out.extend(_leaves(value, path + "."))
        else:
            out.append(path)
    return out


@cache
def _agent_defaults(agent: str) -> dict:
    from omegaconf import OmegaConf

    from repro.config.compose import compose, group_options

    if agent not in group_options("agent"):
        return v2_defaults()
    data = OmegaConf.to_container(compose([f"agent={agent}"]), resolve=True, enum_to_str=True)
    assert isinstance(data, dict)
    return data


def _agent_default(agent: str, key: str) -> Any:
    """Today's default of ``key`` for the agent file ``agent`` (the version-2 default when it is not one)."""
    value = get_key(_agent_defaults(agent), key)
    return get_key(v2_defaults(), key) if value is ABSENT else value


def _config_1_to_2(data: dict) -> dict:
    """Fill the keys a version-1 file lacks (their value then: :data:`V1_OLD_BEHAVIOUR` for its learners, else the
    version-2 default), drop what the learner does not read, and number the file."""
    learner = str(get_key(data, "agent.learner")) if get_key(data, "agent.learner") is not ABSENT \
        else LearnerName.actor_critic.value
    set_key(data, "agent.learner", learner)  # configs written before agent.learner existed: the online learner
    defaults = v2_defaults()
    for key in _leaves(defaults):
        if key == "format" or get_key(data, key) is not ABSENT:
            continue
        parent = key.rpartition(".")[0]
        if parent and any(parent == m or parent.startswith(m + ".") for m in FREE_MAPPINGS):
            continue
        if key in V1_OLD_BEHAVIOUR:
            learners, before = V1_OLD_BEHAVIOUR[key]
            # the listed learners behaved as the old value; any other does not depend on the key: today's default
            # of its agent file
            value = before if learner in learners else _agent_default(str(get_key(data, "agent.name")), key)
        else:
            value = get_key(defaults, key)
        set_key(data, key, copy.deepcopy(value))
    prune_unread(data)
    return {"format": 2, **data}


def _config_2_to_3(data: dict) -> dict:
    """``agent.fast`` (issue 26): a run written before it existed ran the plain path."""
    if get_key(data, "agent.fast") is ABSENT:
        set_key(data, "agent.fast", False)
    return {**data, "format": 3}


def _config_3_to_4(data: dict) -> dict:
    """The learners' sections left ``AgentConfig`` for their agent files (issue 35): a run holds its learner's own
    section only, as every file of version 2 or 3 already did (``prune_unread``, which the step applies again)."""
    return {**prune_unread(data), "format": 4}


CONFIG_STEPS: dict[int, Callable[[dict], dict]] = {1: _config_1_to_2, 2: _config_2_to_3, 3: _config_3_to_4}


def config_version(data: dict) -> int:
    """The format version of a config.yaml's contents (1 when it has no ``format`` key)."""
    version = data.get("format", 1)
    if not isinstance(version, int) or isinstance(version, bool):
        raise FormatError(f"config.yaml: format {version!r} is not a version number")
    return version


def migrate_config(data: dict, owned: bool = False) -> dict:
    """``data`` (a config.yaml's contents) in the current format, step by step. ``data`` is not changed, unless the
    caller ``owned`` it (just parsed it, say): then it is not copied first, and may be changed or returned."""
    out = data if owned else copy.deepcopy(data)
    version = config_version(out)
    if version > CONFIG_FORMAT:
        raise FormatError(f"config.yaml is format {version}; this version of taco-repro reads up to "
                          f"{CONFIG_FORMAT}: upgrade it")
    while version < CONFIG_FORMAT:
        out = CONFIG_STEPS[version](out)
        version = config_version(out)
    return out


# ------------------------------------------------------------------------------------------------ meta.json
def _meta_1_to_2(meta: dict, done: dict | None) -> dict:
    """Number the file; a done run's one reached budget is its DONE (frame online, update offline)."""
    budgets = []
    if done is not None:
        reached = done.get("frame", done.get("update"))
        if isinstance(reached, int):
            budgets.append({"budget": reached, "finished": done.get("finished")})
    return {**meta, "format": 2, "budgets": budgets, "extensions": [], "migrations": []}


META_STEPS: dict[int, Callable[[dict, dict | None], dict]] = {1: _meta_1_to_2}


def migrate_meta(meta: dict, done: dict | None) -> dict:
    """``meta`` (a meta.json's contents, not changed) in the current format; ``done`` is the run's DONE file, if
    any (a version-1 meta.json does not list the budgets the run reached)."""
    out = copy.deepcopy(meta)
    version = out.get("format", 1)
    if not isinstance(version, int) or isinstance(version, bool) or version > META_FORMAT:
        raise FormatError(f"meta.json: format {version!r}; this version of taco-repro reads up to {META_FORMAT}")
    while version < META_FORMAT:
        out = META_STEPS[version](out, done)
        version = out["format"]
    return out
