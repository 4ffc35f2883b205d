"""Compose the packaged Hydra config (compose API) and validate it against the typed schema."""

from __future__ import annotations

import dataclasses
import difflib
import functools
import os
import re
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, cast

import yaml
from omegaconf import DictConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException, ValidationError

from repro.config.bounds import NAME_PATTERN, Check, declared, is_mapping
from repro.config.errors import UserError
from repro.config.plugins import PluginError, load_factory
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
    section_type,
    unread_keys,
)

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
NAME_RE = re.compile(NAME_PATTERN)  # a run directory component (repro/config/bounds.py A_NAME)


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
    """The agent files whose learner trains offline (`repro bench offline --agent`'s choices), in the learners'
    registration order, each learner's agents by name."""
    return _agents_of(offline=True)


def online_agents() -> tuple[str, ...]:
    """The agent files whose learner trains in an environment (`repro bench update --agent`'s choices), ordered as
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
    Enum there), then every field's declared allowed values (:func:`_check_fields`) and the rules that relate
    fields (:func:`_check_learner`)."""
    learner: str | None = None  # known once the schema is made
    try:
        OmegaConf.resolve(raw)
        schema = _structure(raw)
        learner = str(OmegaConf.select(raw, "agent.learner"))
        for key, kind, _ in _run_fields(learner):  # before the merge reads a number as a flag
            if _plain(kind) is bool:
                _check_flag(key, kind, OmegaConf.select(raw, key, default=None))
        cfg = cast(DictConfig, OmegaConf.merge(schema, raw))  # dict merged into dict
    except OmegaConfBaseException as exc:
        raise ConfigError(_type_refusal(exc, raw, learner)) from None
    missing = sorted(OmegaConf.missing_keys(cfg))  # the schema gives no value: the YAML gives every one
    if missing:
        raise ConfigError(f"no value for {', '.join(missing)} (the packaged YAML under repro/conf/ gives every "
                          "field one; a config file or override must not drop it).")
    _check_objectives(cfg)
    _check_fields(cfg)
    check_option("task", str(cfg.task.name), " in task.name (a task file of repro/conf/task/ names each task)")
    _check_learner(cfg)
    return cfg


def _type_refusal(exc: OmegaConfBaseException, raw: DictConfig, learner: str | None) -> str:
    """The one line for a value OmegaConf refused at the key it names, in this module's words (:func:`_type_text`,
    as the objectives' parameters are); ``learner``: the run's, None when the error came before the schema was made
    (an interpolation)."""
    key = getattr(exc, "full_key", None)
    allowed = choice_fields().get(str(key))
    if key and allowed is not None:  # OmegaConf's own message names Enum members, not the values to write
        value = OmegaConf.select(raw, str(key), default=None)
        return f"{key}={value} is not one of {', '.join(allowed.values())}."
    kind = _kind_at(str(key), learner) if key and learner is not None else None
    given = OmegaConf.select(raw, str(key), default=None) if key else None
    if (is_mapping(kind) or _is_section(kind)) and not isinstance(given, DictConfig):
        if not _is_section(kind):
            return f"{key} is a mapping: set its entries one by one, e.g. {key}.<name>=... (got {given!r})."
        names = [f.name for f in dataclasses.fields(cast(type, kind))]
        return (f"{key} is a section ({', '.join(names)}): set its values one by one, e.g. {key}.{names[0]}=... "
                f"(got {given!r}).")
    if isinstance(exc, ValidationError) and _is_plain(kind):
        return f"{key} must be {_type_text(kind)} (got {given!r})."
    first = str(exc).strip().splitlines()[0]
    return f"{key}: {first}" if key else first


Field = tuple[str, Any, "Check | None"]  # dotted key, type, declared check (repro/config/bounds.py)


@functools.cache
def _declared(section: type, prefix: str) -> tuple[Field, ...]:
    return tuple(declared(section, prefix))


def _run_fields(learner: str) -> tuple[Field, ...]:
    """Every field of a run of ``learner``: :class:`RunConfig`'s, then its learner's own section (``agent.<learner>``,
    when it registers one), sections included (as their dataclass types)."""
    section = section_type(learner)
    own = ((f"agent.{learner}", section, None), *_declared(section, f"agent.{learner}.")) if section else ()
    return (*_declared(RunConfig, ""), *own)


def _params_fields(objective: str) -> tuple[Field, ...]:
    """The fields of a registered objective's parameters (``agent.objective_params.<objective>.<setting>``)."""
    spec = objective_specs().get(objective)
    if spec is None or spec.params is None:
        return ()
    return _declared(spec.params, f"agent.objective_params.{objective}.")


def _check_fields(cfg: DictConfig) -> None:
    """The one check of every declared allowed value (a ``Bound`` or a ``Text`` in a field's annotation,
    repro/config/bounds.py: the run config's fields, its learner's section's, the parameters of the objectives it
    names), before anything is built or written: torch's optimizers and the networks would otherwise reject such a
    value with a traceback after the run directory exists. A key the run does not read
    (:func:`repro.config.schema.unread_keys`) and a null value are not checked."""
    learner = str(cfg.agent.learner)
    unread = unread_keys(learner)
    fields = [*_run_fields(learner), *(f for name in cfg.agent.objectives for f in _params_fields(str(name)))]
    for key, _, check in fields:
        if check is None or any(key == k or key.startswith(f"{k}.") for k in unread):
            continue
        line = check.refusal(key, OmegaConf.select(cfg, key, default=None))
        if line is not None:
            raise ConfigError(line)


def _kind_at(key: str, learner: str) -> Any:
    """The type the schema gives the value at ``key`` in a run of ``learner`` (a mapping's entry: its values'
    type), None when it gives none."""
    kinds = {k: kind for k, kind, _ in _run_fields(learner)}
    if key in kinds:
        return kinds[key]
    parent = kinds.get(key.rpartition(".")[0])
    return typing.get_args(parent)[1] if is_mapping(parent) and len(typing.get_args(parent)) == 2 else None


def _is_section(kind: Any) -> bool:
    return isinstance(kind, type) and dataclasses.is_dataclass(kind)


def _plain(kind: Any) -> Any:
    """``kind`` without ``Optional``: ``int`` for ``Optional[int]``."""
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    return args[0] if len(args) == 1 and type(None) in typing.get_args(kind) else kind


def _is_plain(kind: Any) -> bool:
    """Whether ``kind`` is a plain value's type (a flag, a number, a string; Optional or not)."""
    return _plain(kind) in (bool, int, float, str)


def _check_flag(key: str, kind: Any, value: Any) -> None:
    """ConfigError for a number where the schema has a flag (``agent.fast=2``): OmegaConf would read any number but 0
    as true and 0 as false."""
    if _plain(kind) is bool and isinstance(value, (int, float)) and not isinstance(value, bool):
        raise ConfigError(f"{key} must be {_type_text(kind)} (got {value!r}).")


def _check_objectives(cfg: DictConfig) -> None:
    """Every name of ``agent.objectives`` and ``agent.objective_params`` is a registered objective, and every
    objective's parameters read as its registered ``params`` (:func:`objective_params`). The config itself is left as
    given (its run's identity). (A weight's allowed values are declared beside ``AgentConfig.objectives``.)"""
    for section in ("objectives", "objective_params"):
        for name in cfg.agent[section]:
            if name not in objective_names():
                raise ConfigError(unknown_objective(str(name), f"agent.{section}"))
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
    for key, value in given.items():
        _check_flag(f"{where}.{key}", hints[key], value)
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
    """The rules that relate fields to ``agent.learner`` (a registered learner, checked by :func:`_structure`):
    ``offline.dataset`` is given to offline learners only, and is a folder (made one spelling) or a dataset kind; an
    online run's horizon fits its replay and episodes (:func:`_check_horizon`); what the learner resolves from its
    config (:func:`_resolve`)."""
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
