"""Compose the packaged Hydra config (compose API) and validate it against the typed schema."""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import os
import re
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, cast

import yaml
from omegaconf import BooleanNode, DictConfig, FloatNode, IntegerNode, OmegaConf, StringNode, open_dict
from omegaconf.errors import OmegaConfBaseException, ValidationError

from repro.config.errors import UserError
from repro.config.plugins import Bound, PluginError, bound_text, in_bound, load_factory
from repro.config.schema import (
    AGENT_FIELDS,
    BUDGET_KEYS,
    AgentConfig,
    Choice,
    LearnerName,
    RunConfig,
    choice_fields,
    is_offline,
    learner_names,
    learner_specs,
    objective_names,
    objective_specs,
    plugin_conf_dirs,
    registered_ranges,
    section_type,
    unread_keys,
)

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")


class ConfigError(UserError, ValueError):
    """A config problem, explained in one line."""


def is_folder_value(value: str) -> bool:
    """An ``offline.dataset`` value naming a folder (has a '/', starts with '~', or is '.'/'..'), not a kind."""
    return "/" in value or value.startswith("~") or value in (".", "..")


def conf_dirs() -> tuple[Path, ...]:
    """The packaged conf folder, then the registered plugins' (their agent files compose as the packaged ones)."""
    try:
        return (CONF_DIR, *(Path(d) for d in plugin_conf_dirs()))
    except PluginError as exc:
        raise ConfigError(str(exc)) from None


def config_digest() -> str:
    """A digest of everything :func:`compose` reads: the conf folders' files (the plugins' included), this package's
    code, and each registered plugin's entry point, distribution version and module source. Equal digests and equal
    overrides compose equal configs (``repro plan --claims`` keeps compositions under it)."""
    import hashlib
    import importlib.util
    from importlib.metadata import entry_points

    from repro.config.plugins import LEARNER_GROUP, OBJECTIVE_GROUP

    h = hashlib.sha1()
    folders = [*conf_dirs(), Path(__file__).resolve().parent]
    for folder in folders:
        for path in sorted(folder.rglob("*")):
            if path.is_file() and path.suffix in (".py", ".yaml", ".yml", ".json", ".csv"):
                h.update(str(path).encode())
                h.update(path.read_bytes())
    for group in (LEARNER_GROUP, OBJECTIVE_GROUP):
        for ep in sorted(entry_points(group=group), key=lambda e: e.name):
            dist = getattr(ep, "dist", None)
            release = f"{dist.name}={dist.version}" if dist is not None else ""
            h.update(f"{group}|{ep.name}|{ep.value}|{release}".encode())
            try:
                spec = importlib.util.find_spec(ep.module)
            except (ImportError, ValueError):
                spec = None
            if spec is not None and spec.origin and os.path.isfile(spec.origin):
                h.update(Path(spec.origin).read_bytes())
    return h.hexdigest()


def group_options(group: str) -> list[str]:
    """Names of the YAML files in a config group (e.g. ``task`` or ``agent``), the plugins' included."""
    return sorted({p.stem for conf in conf_dirs() for p in (conf / group).glob("*.yaml")})


def agent_learner(agent: str) -> str:
    """The ``agent.learner`` the agent file ``agent`` composes to, read from YAML without composing (fast enough
    for command-line checks): its own ``learner`` key, else that of the last agent file its ``defaults`` inherit,
    else conf/config.yaml's. tests/test_plugins.py checks it against Hydra's composition."""
    path = next(p for p in (conf / "agent" / f"{agent}.yaml" for conf in conf_dirs()) if p.is_file())
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if "learner" in data:
        return str(data["learner"])
    agents = group_options("agent")
    for entry in reversed(data.get("defaults") or []):
        parent = entry.partition("@")[0] if isinstance(entry, str) else ""
        if parent in agents:
            return agent_learner(parent)
    top = yaml.safe_load((CONF_DIR / "config.yaml").read_text(encoding="utf-8"))
    return str(top["agent"]["learner"])


def offline_agents() -> tuple[str, ...]:
    """The agent files whose learner trains offline (`repro bench --offline`'s list), in the learners' registration
    order, each learner's agents by name."""
    return _agents_of(offline=True)


def online_agents() -> tuple[str, ...]:
    """The agent files whose learner trains in an environment (`repro bench --algo`'s choices), ordered as
    :func:`offline_agents`."""
    return _agents_of(offline=False)


def _agents_of(offline: bool) -> tuple[str, ...]:
    order = {name: i for i, name in enumerate(learner_names())}
    learners = {agent: agent_learner(agent) for agent in group_options("agent")}
    chosen = [a for a, learner in learners.items() if learner in order and is_offline(learner) == offline]
    return tuple(sorted(chosen, key=lambda a: (order[learners[a]], a)))


def config_groups() -> dict[str, list[str]]:
    """Every config group of the packaged config -> its option names."""
    return {d.name: group_options(d.name) for d in sorted(CONF_DIR.iterdir()) if d.is_dir()}


def close_matches(name: str, options: Iterable[str]) -> str:
    """`` Did you mean: a, b?`` or `` Known: ...`` (options in the order given) for an error line; empty when
    there are no options."""
    options = list(dict.fromkeys(options))
    matches = difflib.get_close_matches(name, options, n=3, cutoff=0.5)
    if matches:
        return f" Did you mean: {', '.join(matches)}?"
    return f" Known: {', '.join(options)}." if options else ""


def check_option(group: str, value: str, where: str = "") -> None:
    """Raise ConfigError when ``value`` is not an option of config ``group``; ``where`` is added after the value
    (e.g. `` in --set task=x``)."""
    options = group_options(group)
    if value not in options:
        raise ConfigError(f"unknown {group} '{value}'{where}." + close_matches(value, options))


def _check_group_overrides(overrides: list[str]) -> None:
    for ov in overrides:
        key, sep, value = ov.partition("=")
        if not sep:
            raise ConfigError(f"override '{ov}' is not key=value.")
        key = key.lstrip("+~")
        if key in ("agent", "task", "profile"):
            check_option(key, value)


def _check_keys(overrides: list[str], cfg: DictConfig) -> None:
    for ov in overrides:
        key = ov.partition("=")[0]
        if key.startswith(("+", "~")) or key in ("agent", "task", "profile"):
            continue
        if OmegaConf.select(cfg, key, default="__missing__") == "__missing__":
            parent, _, leaf = key.rpartition(".")
            node = OmegaConf.select(cfg, parent) if parent else cfg
            siblings = list(node.keys()) if isinstance(node, DictConfig) else []
            raise ConfigError(f"unknown config key '{key}'." + close_matches(leaf, [str(s) for s in siblings]))


def compose(overrides: list[str] | tuple[str, ...] = ()) -> DictConfig:
    """Resolve the config for ``overrides`` (Hydra syntax); raise ConfigError with one line on bad input."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException

    overrides = list(overrides)
    _check_group_overrides(overrides)
    plugins = [f"'file://{conf}'" for conf in conf_dirs()[1:]]  # the plugins' agent files (Hydra's search path)
    search = [f"hydra.searchpath=[{','.join(plugins)}]"] if plugins else []
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            raw = hydra_compose(config_name="config", overrides=[*overrides, *search])
    except (HydraException, OmegaConfBaseException) as exc:
        # Hydra's messages are multi-line; keep the first line and name close keys when possible.
        first = str(exc).strip().splitlines()[0]
        for ov in overrides:
            key = ov.partition("=")[0].lstrip("+~")
            if f"'{key}'" in first or key in first:
                _check_objective_key(ov)
                base = _compose_choices(overrides)
                try:
                    _check_keys([ov], base)
                except ConfigError as err:
                    raise ConfigError(str(err)) from None
        raise ConfigError(first) from None
    finally:
        GlobalHydra.instance().clear()
    return validate(raw)


def unknown_objective(name: str, where: str) -> str:
    """The one line for an objective name nobody registered, found in ``where`` (``agent.objectives``): the close
    names, then every registered objective (the plugins' included)."""
    names = objective_names()
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.5)
    hint = f" Did you mean: {', '.join(close)}?" if close else ""
    return f"unknown objective '{name}' in {where}.{hint} Registered objectives: {', '.join(names)}."


def _check_objective_key(override: str) -> None:
    """ConfigError for an override ``agent.objectives.<name>=w`` or ``agent.objective_params.<name>.<setting>=v``
    that Hydra refused: a name nobody registered, a setting the objective does not have, or (both known) a key the
    agent file does not hold, which needs Hydra's ``+``. Nothing for any other key."""
    key, _, value = override.partition("=")
    parts = key.lstrip("+~").split(".")
    if len(parts) < 3 or parts[0] != "agent" or parts[1] not in ("objectives", "objective_params"):
        return
    try:
        names = objective_names()
    except PluginError as exc:
        raise ConfigError(str(exc)) from None
    name, section = parts[2], f"agent.{parts[1]}"
    if name not in names:
        raise ConfigError(unknown_objective(name, section))
    if section == "agent.objective_params" and len(parts) == 4:
        _params_type(name, {parts[3]: None})  # an unknown setting, or one of an objective that takes none
    if not key.startswith(("+", "~")) and len(parts) == (3 if section == "agent.objectives" else 4):
        raise ConfigError(f"{key.lstrip('+~')} is not in the agent file's config: add it with +{key}={value}.")


_CHOICES: dict[tuple[str, ...], DictConfig] = {}  # agent/task/profile overrides -> their config (() the base)
_GROUPS = ("agent", "task", "profile")


def _compose_choices(overrides: list[str]) -> DictConfig:
    """The config of the agent, task and profile that ``overrides`` choose, with nothing else set (cached): the keys
    a misspelt key is matched against are the chosen agent file's (``agent=td3bc agent.alphaa=1`` suggests TD3+BC's
    keys, not the default agent's). The base config when those choices alone do not compose."""
    choices = tuple(ov for ov in overrides if ov.partition("=")[0].lstrip("+~") in _GROUPS)
    if choices not in _CHOICES:
        try:
            _CHOICES[choices] = compose(list(choices))
        except ConfigError:
            if not choices:  # the base itself does not compose: nothing to fall back to
                raise
            return compose_base()
    return _CHOICES[choices]


def compose_base() -> DictConfig:
    """The config with no overrides (cached), for key suggestions."""
    return _compose_choices([])


def validate(raw: DictConfig) -> DictConfig:
    """Resolve interpolations, check types against the schema (a closed set of values is a :class:`Choice`
    Enum there) and the values' ranges."""
    schema: DictConfig | None = None
    try:
        OmegaConf.resolve(raw)
        schema = _structure(raw)
        _check_flags(schema, raw)
        cfg = cast(DictConfig, OmegaConf.merge(schema, raw))  # dict merged into dict
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None)
        allowed = choice_fields().get(str(key))
        if key and allowed is not None:  # OmegaConf's own message names Enum members, not the values to write
            value = OmegaConf.select(raw, str(key), default=None)
            raise ConfigError(f"{key}={value} is not one of {', '.join(allowed.values())}.") from None
        # what the schema holds at the key (None when the error came before the schema was made: an interpolation)
        node = _node_at(schema, str(key)) if key and schema is not None else None
        given = OmegaConf.select(raw, str(key), default=None) if key else None
        if isinstance(node, DictConfig) and not isinstance(given, DictConfig):
            section = node._metadata.ref_type
            if not (isinstance(section, type) and dataclasses.is_dataclass(section)):
                raise ConfigError(f"{key} is a mapping: set its entries one by one, e.g. {key}.<name>=... (got "
                                  f"{given!r}).") from None
            names = [f.name for f in dataclasses.fields(section)]
            raise ConfigError(f"{key} is a section ({', '.join(names)}): set its values one by one, e.g. "
                              f"{key}.{names[0]}=... (got {given!r}).") from None
        kind = _leaf_kind(node) if isinstance(exc, ValidationError) else None
        if kind is not None:  # in this module's words (_type_text), as the objectives' parameters are
            raise ConfigError(f"{key} must be {_type_text(kind)} (got {given!r}).") from None
        first = str(exc).strip().splitlines()[0]
        raise ConfigError(f"{key}: {first}" if key else first) from None
    missing = sorted(OmegaConf.missing_keys(cfg))  # the schema has types only: the YAML gives every value
    if missing:
        raise ConfigError(f"no value for {', '.join(missing)} (the packaged YAML under repro/conf/ gives every "
                          "field one; a config file or override must not drop it).")
    for key in ("experiment", "variant", "task.name", "agent.name"):
        value = str(OmegaConf.select(cfg, key))
        if not NAME_RE.match(value):
            raise ConfigError(f"{key}='{value}' may only contain letters, digits, '_', '.' and '-'.")
    check_option("task", str(cfg.task.name), " in task.name (a task file of repro/conf/task/ names each task)")
    if not str(cfg.runtime.results_root).strip():  # `runtime.results_root=$UNSET`: runs would land in the cwd
        raise ConfigError("runtime.results_root is empty: name the folder the runs go under (default: runs).")
    _check_objectives(cfg)
    _check_ranges(cfg)
    if cfg.seed < 0:
        raise ConfigError(f"seed must be >= 0 (got {cfg.seed}).")
    if cfg.env.distracting_dims < 0 or cfg.train.eval_episodes < 0:
        raise ConfigError("env.distracting_dims and train.eval_episodes must be >= 0.")
    if cfg.train.video_size < 16 or cfg.train.video_size % 2:
        raise ConfigError(f"train.video_size must be an even number >= 16 (got {cfg.train.video_size}).")
    _check_learner(cfg)
    return cfg


def _section(node: Any) -> Any:
    """A schema node, with a section the schema types but leaves to the YAML (``agent``: MISSING) as its type's
    (made once per type: the callers only read it)."""
    kind = node._metadata.ref_type if isinstance(node, DictConfig) and node._is_missing() else None
    return _structured(kind) if isinstance(kind, type) and dataclasses.is_dataclass(kind) else node


@functools.cache
def _structured(kind: type) -> DictConfig:
    return OmegaConf.structured(kind)


_LEAF_KINDS = {BooleanNode: bool, IntegerNode: int, FloatNode: float, StringNode: str}


def _node_at(schema: DictConfig, key: str) -> Any:
    """The schema's node at ``key`` (sections the YAML fills as their types'), None when the schema has none."""
    node: Any = schema
    for part in key.split("."):
        node = _section(node)
        if not isinstance(node, DictConfig) or part not in node.keys():  # ``in`` is False for a MISSING value
            return None
        node = node._get_node(part)
    return node


def _leaf_kind(node: Any) -> Any:
    """The type a schema node gives its value (``int``, ``float | None`` ...), None when it is not a plain value."""
    kind = _LEAF_KINDS.get(type(node))
    return None if kind is None else kind | None if node._is_optional() else kind


def _check_flags(schema: DictConfig, raw: DictConfig, prefix: str = "") -> None:
    """ConfigError for a number where the schema has a flag (``agent.fast=2``): OmegaConf would read any number but 0
    as true and 0 as false."""
    for key in map(str, schema):
        node, given = _section(schema._get_node(key)), raw._get_node(key) if key in raw else None
        if isinstance(node, DictConfig) and isinstance(given, DictConfig):
            _check_flags(node, given, f"{prefix}{key}.")
        elif isinstance(node, BooleanNode) and given is not None and not isinstance(given, DictConfig):
            value = given._value()
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                raise ConfigError(f"{prefix}{key} must be {_type_text(_leaf_kind(node))} (got {value!r}).")


def _check_objectives(cfg: DictConfig) -> None:
    """Every name of ``agent.objectives`` and ``agent.objective_params`` is a registered objective, and every
    objective's parameters read as its registered ``params`` (:func:`objective_params`). The config itself is left as
    given (its run's identity)."""
    for section in ("objectives", "objective_params"):
        for name in cfg.agent[section]:
            if name not in objective_names():
                raise ConfigError(unknown_objective(str(name), f"agent.{section}"))
    for name, weight in cfg.agent.objectives.items():
        if not (0.0 <= weight < math.inf):  # NaN included
            raise ConfigError(f"agent.objectives.{name} is a loss weight: a finite number >= 0, 0 disables it "
                              f"(got {weight}).")
    for name, given in cfg.agent.objective_params.items():
        objective_params(str(name), given)


def _type_text(kind: Any) -> str:
    """How an error line names a parameter's type: ``an integer``, ``a number``, ``true or false``, ``a string``,
    ``one of a, b`` (a :class:`Choice`), each ``or null`` when Optional."""
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    if len(args) == 1 and type(None) in typing.get_args(kind):
        return f"{_type_text(args[0])} or null"
    if isinstance(kind, type) and issubclass(kind, Choice):
        return f"one of {', '.join(kind.values())}"
    words = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}
    return words.get(kind, getattr(kind, "__name__", str(kind)))


def _params_type(name: str, given: Mapping[Any, Any]) -> type | None:
    """The registered ``params`` dataclass of objective ``name`` (None when it takes none); ConfigError (one line)
    when ``given`` names a setting it does not have."""
    spec = objective_specs()[name]
    where = f"agent.objective_params.{name}"
    if spec.params is None:
        if given:
            raise ConfigError(f"{where}: objective '{name}' takes no parameters (got {', '.join(map(str, given))}).")
        return None
    known = [f.name for f in dataclasses.fields(spec.params)]
    for key in given:
        if key not in known:
            raise ConfigError(f"unknown setting {where}.{key} of objective '{name}'." + close_matches(str(key), known))
    return spec.params


def objective_params(name: str, given: Any = None) -> Any:
    """The parameters of the registered objective ``name`` typed: an instance of its ``ObjectiveSpec.params``, the
    values ``given`` (``agent.objective_params.<name>``: a mapping, or None) over the dataclass's defaults; None for
    an objective that takes none. ConfigError (one line) for a setting it does not have or a value of the wrong type
    (a float where an integer is meant included: it is refused, never truncated). Called by :func:`validate` before
    anything is written, and by the agent that builds the objective."""
    where = f"agent.objective_params.{name}"
    if isinstance(given, DictConfig):
        given = OmegaConf.to_container(given, resolve=True)
    given = {} if given is None else given
    if not isinstance(given, Mapping):
        raise ConfigError(f"{where} must be a mapping of setting: value (got {given!r}).")
    kind = _params_type(name, given)
    if kind is None:
        return None
    hints = typing.get_type_hints(kind)
    node = OmegaConf.structured(kind)
    _check_flags(node, OmegaConf.create(dict(given)), f"{where}.")
    for key, value in given.items():
        try:
            node[key] = value
        except OmegaConfBaseException:
            raise ConfigError(f"{where}.{key} must be {_type_text(hints[key])} (got {value!r}).") from None
    return OmegaConf.to_object(node)


def _structure(raw: DictConfig) -> DictConfig:
    """The typed schema for ``raw``: :class:`RunConfig`, and the section its learner registers (``agent.<learner>``:
    only that learner's runs hold it). Another registered learner's section in ``raw`` (``++agent.dt.batch_size=8``
    given to every agent of a sweep) is removed from it, unread. ConfigError for a learner nobody registered."""
    learner = str(OmegaConf.select(raw, "agent.learner", default=""))
    try:
        names, _ = learner_names(), objective_names()  # every registration loads (one line if one does not)
    except PluginError as exc:
        raise ConfigError(str(exc)) from None
    if learner not in names:
        raise ConfigError(f"agent.learner={learner} is not one of {', '.join(names)}.")
    agent_node = raw.get("agent")
    if isinstance(agent_node, DictConfig):
        with open_dict(agent_node):
            for other in names:
                if other != learner and other in agent_node and other not in AGENT_FIELDS:
                    agent_node.pop(other)
    schema = OmegaConf.structured(RunConfig)
    section = section_type(learner)
    if section is not None:
        agent = OmegaConf.structured(AgentConfig)
        with open_dict(agent):
            agent[learner] = OmegaConf.structured(section)
        schema.agent = agent
    return schema


# The allowed values of each numeric key every run holds (counts, sizes, rates): key -> a bound
# (repro/config/plugins.py ``Bound``: (low, inclusive) or (low, inclusive, high, inclusive)); a learner's own section
# and the objectives' parameters are bounded by their registrations (``ranges``). Checked before anything is built
# or written: torch's optimizers and the networks would otherwise reject such a value with a traceback after the run
# directory exists.
RANGES: dict[str, Bound] = {
    **{key: (1, True) for key in ("agent.K", "agent.batch_size", "agent.nstep", "agent.stddev_schedule.step_scale",
                                  "env.action_repeat", "env.frame_stack", "train.frames", "train.eval_every_frames",
                                  "train.update_every_steps", "replay.capacity", "agent.feature_dim",
                                  "agent.hidden_dim", "agent.action_hidden_dim", "agent.latent_action_dim")},
    "agent.lr": (0.0, False),  # and finite (FINITE)
    "agent.stddev_clip": (0.0, True),
    "agent.discount": (0.0, True, 1.0, True),
    "agent.critic_target_tau": (0.0, True, 1.0, True),
    "env.image_size": (16, True),
    "train.seed_frames": (0, True),
    "train.explore_steps": (0, True),
    "train.checkpoint_every_episodes": (1, True),  # the loop takes the episode count modulo it
    "env.max_episode_frames": (1, True),  # null: the suite's own episode length
}
FINITE = ("agent.lr",)  # an infinite learning rate trains NaN weights (NaN is in no range: torch's Adam refuses it)


def _check_ranges(cfg: DictConfig) -> None:
    """One line for a value out of its range (:data:`RANGES`, and the ranges registered with the run's learner and
    objectives), before anything is built or written. A null value is not checked."""
    ranges = {**RANGES, **registered_ranges(str(cfg.agent.learner), [str(k) for k in cfg.agent.objectives])}
    for key, bound in ranges.items():
        value = OmegaConf.select(cfg, key)
        if value is None:
            continue
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ConfigError(f"{key} must be a number {bound_text(bound)} (got {value!r}).")
        if not in_bound(value, bound):
            raise ConfigError(f"{key} must be {bound_text(bound)} (got {value}).")
        if key in FINITE and math.isinf(value):
            raise ConfigError(f"{key} must be a finite number {bound_text(bound)} (got {value}).")


def _check_horizon(cfg: DictConfig) -> None:
    """An online run samples transitions with ``max(agent.K, agent.nstep)`` steps ahead in their episode
    (repro/data/replay.py). That needs a replay of at least that many slots plus the frame stack, and episodes at
    least that long where ``env.max_episode_frames`` cuts them (``profile=tiny``: 50 agent steps); otherwise nothing
    can be sampled, which failed at the first update, after the run directory was written. The suites' own episode
    lengths (DMC: 500 agent steps at action repeat 2) are not known here and not checked."""
    horizon, stack = max(cfg.agent.K, cfg.agent.nstep), cfg.env.frame_stack
    if cfg.replay.capacity < horizon + stack:  # the ring holds a transition with its stack and horizon from there
        raise ConfigError(f"replay.capacity={cfg.replay.capacity} holds no transition {horizon} steps ahead "
                          f"(max(agent.K, agent.nstep)) with its stack of {stack} frames: it must be >= "
                          f"{horizon + stack}.")
    frames = cfg.env.max_episode_frames
    if frames is None:
        return
    steps = max(1, int(frames) // int(cfg.env.action_repeat))
    if horizon > steps:
        raise ConfigError(f"agent.K={cfg.agent.K} and agent.nstep={cfg.agent.nstep} look further ahead than an "
                          f"episode of {steps} agent steps (env.max_episode_frames={frames} / env.action_repeat="
                          f"{cfg.env.action_repeat}): each must be <= {steps}.")


def _check_learner(cfg: DictConfig) -> None:
    """``offline.*`` is consistent with ``agent.learner`` (a registered learner, checked by :func:`_structure`)."""
    learner = str(cfg.agent.learner)
    dataset = cfg.offline.dataset
    if not is_offline(learner):
        if dataset is not None:
            raise ConfigError(f"offline.dataset is read by offline learners only (agent.learner={learner} "
                              "trains online); pick an offline agent, e.g. agent=bc.")
        _check_horizon(cfg)
        return
    if dataset is not None and is_folder_value(str(dataset)):
        # A folder is identity (the run directory's dataset tag): one folder, one spelling. ds/x, ds/x/, ./ds/x
        # and a symlink to it all become its absolute real path (an absolute real path is kept as written).
        dataset = cfg.offline.dataset = os.path.realpath(os.path.expanduser(str(dataset)))
    if dataset is not None and not is_folder_value(str(dataset)) and not NAME_RE.match(str(dataset)):
        raise ConfigError(f"offline.dataset='{dataset}': a dataset kind may only contain letters, digits, '_', '.' "
                          "and '-' (a folder needs a '/', e.g. ./my_dataset).")
    for key in ("offline.updates", "offline.eval_every_updates", "offline.checkpoint_every_updates",
                "offline.log_every_updates"):
        if OmegaConf.select(cfg, key) < 1:
            raise ConfigError(f"{key} must be >= 1 (got {OmegaConf.select(cfg, key)}).")
    if cfg.offline.eval_episodes < 0:
        raise ConfigError(f"offline.eval_episodes must be >= 0 (got {cfg.offline.eval_episodes}).")
    _resolve(cfg)


def _resolve(cfg: DictConfig) -> None:
    """What the run's learner resolves from its config (``LearnerSpec.resolve``: CQL's Table-6 alpha), in place."""
    spec = learner_specs().get(str(cfg.agent.learner))
    if spec is None or spec.resolve is None:
        return
    try:
        resolve = load_factory(spec, "resolve")
        assert callable(resolve)
        resolve(cfg)
    except (PluginError, ValueError) as exc:
        raise ConfigError(str(exc).splitlines()[0]) from None


def typed(cfg: DictConfig) -> RunConfig:
    """The config as typed dataclasses."""
    return OmegaConf.to_object(cfg)  # type: ignore[return-value]


# Keys outside ``runtime`` that change no logged number (what is watched, not what is trained): a run resumed
# with another value is the same run.
NON_IDENTITY_KEYS = ("train.save_video", "train.video_every", "train.video_size")


class _Absent:
    def __repr__(self) -> str:
        return "<absent>"


ABSENT: Any = _Absent()  # what :func:`get_key` gives for a key the dict lacks (shown as <absent> in differences)


def get_key(data: dict, dotted: str) -> Any:
    """The value at the dotted key in the nested dict ``data``, or :data:`ABSENT`."""
    node: Any = data
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return ABSENT
        node = node[part]
    return node


def set_key(data: dict, dotted: str, value: Any) -> None:
    """Set the dotted key in the nested dict ``data``, making the sections it lacks."""
    *parents, leaf = dotted.split(".")
    node = data
    for part in parents:
        node = node.setdefault(part, {})
    node[leaf] = value


def pop_key(data: dict, dotted: str) -> None:
    """Remove the dotted key (a leaf or a whole section) from the nested dict ``data``, in place; absent: nothing."""
    *parents, leaf = dotted.split(".")
    node: object = data
    for part in parents:
        node = node.get(part) if isinstance(node, dict) else None
    if isinstance(node, dict):
        node.pop(leaf, None)


def prune_unread(data: dict) -> dict:
    """``data`` (a config as plain containers) without the keys its learner does not read
    (:func:`repro.config.schema.unread_keys`), in place: what a run's config.yaml holds."""
    learner = str((data.get("agent") or {}).get("learner", LearnerName.actor_critic))
    for key in unread_keys(learner):
        pop_key(data, key)
    return data


def drop_non_identity(data: dict) -> dict:
    """``data`` (a config as plain containers) without ``runtime``, the format number, :data:`NON_IDENTITY_KEYS`
    and the budget (:data:`repro.config.schema.BUDGET_KEYS`), in place."""
    data.pop("runtime", None)
    data.pop("format", None)
    for key in (*NON_IDENTITY_KEYS, *BUDGET_KEYS):
        pop_key(data, key)
    return data


def run_keys(cfg: DictConfig) -> dict:
    """The config as plain containers with only what its learner reads (a Choice as its value): config.yaml."""
    data = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)  # a Choice's name is its value
    assert isinstance(data, dict)
    return prune_unread(data)


def identity(cfg: DictConfig) -> dict:
    """The part of the config that defines a run: what its learner reads, less ``runtime``, the video switches
    and the budget (a larger budget extends the same run)."""
    return drop_non_identity(run_keys(cfg))
