"""The config schema's name tables (repro/config/schema.py) and the registries that must agree with them."""

from __future__ import annotations

import copy
import dataclasses
import functools
import importlib
import math
import typing
from typing import Annotated

import pandas as pd
import pytest
from omegaconf import OmegaConf

from repro.config import schema
from repro.config.bounds import Bound, Text, declared
from repro.config.schema import (
    DatasetKind,
    LearnerName,
    ObjectiveName,
    is_offline,
    normalize_dataset,
)


@pytest.mark.parametrize("module, specs, spec", [
    ("repro.learners.registry", "BUILTIN_LEARNERS",
     schema.LearnerSpec("newname", offline=True, label="New", factory="repro.learners.newname:New")),
    ("repro.agent.objectives", "BUILTIN_OBJECTIVES", schema.ObjectiveSpec("newname", factory="repro.agent.x:New"))])
def test_a_registry_is_built_from_the_registrations_and_names_a_factory_that_does_not_import(
        monkeypatch, module: str, specs: str, spec):
    """The learner and objective tables hold exactly the registered names (no hand table): re-running the registry
    module's import with one registration more gives that name, whose code does not exist here: one line."""
    mod = importlib.import_module(module)
    table = mod.LEARNERS if "learners" in module else mod.OBJECTIVES
    # as a set: another test's monkeypatch.delitem (test_bench) puts a name back at the end of the table
    assert sorted(table) == sorted(s.name for s in (schema.learner_specs() if "learners" in module
                                                    else schema.objective_specs()).values())
    monkeypatch.setattr(schema, specs, (*getattr(schema, specs), spec))
    schema.learner_specs.cache_clear(), schema.objective_specs.cache_clear()
    try:
        with pytest.raises(schema.PluginError, match="^'newname': cannot import its factory .*newname|x") as err:
            importlib.reload(mod)
        assert "\n" not in str(err.value)
    finally:
        monkeypatch.undo()
        schema.learner_specs.cache_clear(), schema.objective_specs.cache_clear()
        importlib.reload(mod)


@dataclasses.dataclass
class _Misdeclared:
    """A section whose bound is on a field that holds no number."""

    lambda_from: Annotated[schema.LambdaFrom, Bound(ge=0)]


def test_a_built_in_registration_is_checked_as_a_plugin_s(monkeypatch):
    """A built-in spec without a factory, or with a bound on a field of its section that holds no number, is refused
    as a plugin's."""
    for spec, message in ((schema.LearnerSpec("newname", offline=True, label="New"), "factory must be 'module:attr"),
                          (schema.LearnerSpec("newname", offline=True, label="New", factory="m:a",
                                              section=_Misdeclared),
                           "section _Misdeclared: field 'lambda_from' has a bound but is LambdaFrom, not a number.")):
        monkeypatch.setattr(schema, "BUILTIN_LEARNERS", (*schema.BUILTIN_LEARNERS, spec))
        schema.learner_specs.cache_clear()
        try:
            with pytest.raises(schema.PluginError, match=f"^built-in learner 'newname': {message}"):
                schema.learner_specs()
        finally:
            monkeypatch.undo()
            schema.learner_specs.cache_clear()


def test_the_offline_flag_is_registry_data():
    assert not is_offline(LearnerName.actor_critic) and not is_offline("actor_critic")
    assert all(is_offline(n) for n in ("bc", "td3bc", "cql", "iql", "dt"))
    assert [s.name for s in schema.BUILTIN_LEARNERS] == list(LearnerName.values())
    assert [s.name for s in schema.BUILTIN_OBJECTIVES] == list(ObjectiveName.values())
    import repro.learners
    import repro.learners.registry

    # no second table (or re-export) of the flag in the learners layer: its users import the schema's
    assert not hasattr(repro.learners, "is_offline") and not hasattr(repro.learners.registry, "is_offline")


def test_every_choice_member_is_named_by_its_value():
    """OmegaConf reads and writes an Enum field by member name: a name other than the value would change the
    YAML a run writes and the overrides it accepts."""
    fields = schema.choice_fields()
    for enum in {*fields.values(), LearnerName, ObjectiveName, DatasetKind}:
        assert all(m.name == m.value for m in enum), enum
        assert all(str(m) == f"{m}" == m.value for m in enum), enum


def test_dataset_kinds_are_one_choice_with_one_normaliser():
    """The kinds in Table 3's order, one spelling for every way the paper, a config or a table writes one, read by
    the config's Table 6 lookup, `repro dataset make` and the analysis alike; an OmegaConf field of the Choice
    reads ``medium-replay`` (a member named by a value that is not a Python name)."""
    from analysis import load, paper
    from analysis.claims import offline
    from repro.config import paper_defaults
    from repro.train import make_dataset

    assert DatasetKind.values() == ("medium", "medium-replay", "full-replay")
    spellings = [("Medium", "medium"), ("medium_replay", "medium-replay"), (" Medium-Replay", "medium-replay"),
                 ("full_replay", "full-replay"), ("Replay", "full-replay")]
    for spelling, kind in spellings:
        assert DatasetKind(normalize_dataset(spelling)) == kind, spelling
    assert normalize_dataset(None) is normalize_dataset(float("nan")) is normalize_dataset("") is None
    assert normalize_dataset("imported-vd4rl") == "imported-vd4rl"  # a dataset's own name keeps its spelling
    assert paper_defaults.cql_alpha("cheetah_run", "medium_replay") == paper_defaults.cql_alpha("cheetah_run",
                                                                                                "medium-replay")
    # the offline claims read the schema's kinds (their module imports them from repro.config.schema)
    assert load.normalize_dataset is paper.normalize_dataset is normalize_dataset and offline.DatasetKind is DatasetKind
    with pytest.raises(make_dataset.MakeError, match="one of medium, medium-replay, full-replay"):
        make_dataset.plan(None, "medium_replay", None, None, 0, None, None, "cpu")  # type: ignore[arg-type]

    @dataclasses.dataclass
    class Section:
        kind: DatasetKind = DatasetKind("medium")  # type: ignore[valid-type]

    cfg = OmegaConf.structured(Section)
    cfg.kind = "medium-replay"
    assert OmegaConf.to_yaml(cfg) == "kind: medium-replay\n" and cfg.kind is DatasetKind("medium-replay")


AGENT_OF_SECTION = {"iql": "iql", "dt": "dt", "td3bc": "td3bc", "learner": "bc"}


@pytest.mark.parametrize("key", sorted(schema.choice_fields()))
def test_a_value_outside_a_choice_is_one_config_error_line_naming_the_allowed_values(key: str):
    """Every Enum-typed field, task.suite and td3bc.lambda_from included (no check read them before the Enums)."""
    from repro.config.compose import ConfigError, compose

    parts = key.split(".")
    agent = AGENT_OF_SECTION.get(parts[1], "taco") if parts[0] == "agent" and len(parts) > 1 else "taco"
    allowed = schema.choice_fields()[key].values()
    with pytest.raises(ConfigError) as err:
        compose([f"agent={agent}", f"{key}=nonsense"])
    assert str(err.value) == f"{key}=nonsense is not one of {', '.join(allowed)}."
    ok = compose([f"agent={agent}", "offline.dataset=medium", f"{key}={allowed[-1]}"] if agent != "taco"
                 else [f"{key}={allowed[-1]}"])
    assert str(OmegaConf.select(ok, key)) == allowed[-1] and key + ": " + allowed[-1] in _yaml_lines(ok)


def _yaml_lines(cfg) -> str:
    """``section.key: value`` lines of the config.yaml text a run writes for ``cfg``."""
    import yaml

    flat = pd.json_normalize(yaml.safe_load(OmegaConf.to_yaml(cfg, resolve=True))).iloc[0].to_dict()
    return "\n".join(f"{k}: {v}" for k, v in flat.items())


def _sections(section: type = schema.RunConfig):
    yield section
    for f in dataclasses.fields(section):
        kind = typing.get_type_hints(section)[f.name]
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            yield from _sections(kind)
    if section is schema.RunConfig:  # the learners' own sections (agent.<learner>), the built-in ones'
        yield from (s.section for s in schema.BUILTIN_LEARNERS if s.section is not None)


def test_the_schema_gives_types_only_and_the_yaml_every_value():
    """One source for each default: no dataclass default repeats a YAML value, and every agent's config is
    complete from the packaged YAML alone."""
    from repro.config.compose import agent_learner, compose, config_groups

    with_default = [f"{s.__name__}.{f.name}" for s in _sections() for f in dataclasses.fields(s)
                    if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING]
    assert not with_default, with_default
    for agent in config_groups()["agent"]:
        learner = agent_learner(agent)
        alpha = ["agent.cql.alpha=1.0"] if learner == "cql" else []
        over = ["offline.dataset=medium", *alpha] if is_offline(learner) else []
        cfg = compose([f"agent={agent}", *over])
        assert not OmegaConf.missing_keys(cfg), agent


def test_a_value_dropped_from_the_yaml_is_one_config_error_line():
    from repro.config.compose import ConfigError, compose

    with pytest.raises(ConfigError, match=r"^no value for agent\.cql\.n_samples \(") as err:
        compose(["agent=cql", "offline.dataset=medium", "~agent.cql.n_samples=10"])  # Hydra deletes it (at this value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("overrides, message", [
    (["agent=iql", "offline.dataset=medium", "agent.iql.expectile=1"], "agent.iql.expectile must be in (0.0, 1.0) "
                                                                      "(got 1.0)."),
    (["agent.discount=1.5"], "agent.discount must be in [0.0, 1.0] (got 1.5)."),
    (["agent=cql", "offline.dataset=medium", "agent.critic_target_tau=-0.1"],
     "agent.critic_target_tau must be in [0.0, 1.0] (got -0.1)."),
    (["agent=dt", "offline.dataset=medium", "agent.dt.dropout=1.0"],
     "agent.dt.dropout must be in [0.0, 1.0) (got 1.0)."),
    (["agent=spr", "agent.objective_params.spr.momentum=1.5"],
     "agent.objective_params.spr.momentum must be in [0.0, 1.0) (got 1.5)."),
])
def test_a_value_above_its_upper_bound_is_one_line_exit_2_before_anything_is_written(tmp_path, overrides, message):
    """Ranges take an upper bound too (issue 35): IQL's expectile was checked only inside its first update (a
    traceback after the run directory existed)."""
    from typer.testing import CliRunner

    from repro_app.cli import app

    out = CliRunner().invoke(app, ["train", *overrides, f"runtime.results_root={tmp_path}"])
    assert out.exit_code == 2 and out.output.strip() == f"error: {message}", out.output
    assert not list(tmp_path.iterdir())


def refusal(overrides: list[str]) -> str:
    """The ConfigError line composing ``overrides`` raises (the test fails if it composes)."""
    from repro.config.compose import ConfigError, compose

    with pytest.raises(ConfigError) as err:
        compose(overrides)
    return str(err.value)


@pytest.mark.parametrize("overrides, message", [
    # the chosen agent file's keys, not the default agent's (TACO has no td3bc section and no alpha)
    (["agent=td3bc", "offline.dataset=medium", "agent.td3bc.alphaa=1"],
     "unknown config key 'agent.td3bc.alphaa'. Did you mean: alpha?"),
    (["agent=td3bc", "offline.dataset=medium", "agent.batchsize=1"],
     "unknown config key 'agent.batchsize'. Did you mean: batch_size?"),
    (["agent=dt", "offline.dataset=medium", "agent.dt.contxt=5"],
     "unknown config key 'agent.dt.contxt'. Did you mean: context?"),
    (["agent=td3bc", "offline.dataset=medium", "agent.alphaa=1"], "unknown config key 'agent.alphaa'. Known: name,"),
])
def test_a_misspelt_key_is_matched_against_the_chosen_agent_file(overrides, message):
    line = refusal(overrides)
    assert line.startswith(message) and "\n" not in line, line
    if "Known:" in message:  # the known keys listed are TD3+BC's file's: its own section among them
        assert line.endswith(", td3bc."), line


@pytest.mark.parametrize("overrides, message", [
    (["agent.fast=2"], "agent.fast must be true or false (got 2)."),  # OmegaConf read it as true
    (["train.save_frames=0"], "train.save_frames must be true or false (got 0)."),  # and this as false
    (["runtime.tensorboard=1.0"], "runtime.tensorboard must be true or false (got 1.0)."),
    (["agent=cql", "offline.dataset=medium", "agent.cql.importance_sampling=0"],  # a learner's own section
     "agent.cql.importance_sampling must be true or false (got 0)."),
])
def test_a_number_for_a_flag_is_one_line(overrides, message):
    from repro.config.compose import compose

    assert refusal(overrides) == message
    flags = compose(["agent.fast=true", "train.save_frames=false", "runtime.tensorboard=true"])  # words still read
    assert flags.agent.fast is True and flags.train.save_frames is False and flags.runtime.tensorboard is True


@pytest.mark.parametrize("overrides, message", [
    (["agent.lr=nan"], "agent.lr must be > 0.0 (got nan)."),  # was a traceback from torch's Adam
    (["agent.lr=inf"], "agent.lr must be a finite number > 0.0 (got inf)."),  # trained with NaN weights
    (["agent.stddev_clip=nan"], "agent.stddev_clip must be >= 0.0 (got nan)."),  # NaN is in no range
    (["agent=td3bc", "offline.dataset=medium", "agent.td3bc.alpha=nan"], "agent.td3bc.alpha must be >= 0.0 (got nan)."),
    (["agent.objectives.taco=-1"], "agent.objectives.taco is a loss weight: a finite number >= 0, 0 disables it "
                                   "(got -1.0)."),  # were accepted: the update maximised that loss
    (["agent.objectives.curl=nan"], "agent.objectives.curl is a loss weight: a finite number >= 0, 0 disables it "
                                    "(got nan)."),
    (["agent.objectives.reward=inf"], "agent.objectives.reward is a loss weight: a finite number >= 0, 0 disables it "
                                      "(got inf)."),
])
def test_a_value_no_run_can_train_with_is_one_line(overrides, message):
    from repro.config.compose import compose

    assert refusal(overrides) == message
    assert compose(["agent.objectives.curl=0", "agent.lr=1e-3"]).agent.objectives.curl == 0.0  # 0 disables one


@pytest.mark.parametrize("overrides, message", [
    # in the words the objectives' parameters use, not OmegaConf's ("Value 'abc' of type 'str' could not be ...")
    (["agent.K=abc"], "agent.K must be an integer (got 'abc')."),
    (["train.frames=1e6"], "train.frames must be an integer (got 1000000.0)."),
    (["agent.lr=fast"], "agent.lr must be a number (got 'fast')."),
    (["agent.fast=maybe"], "agent.fast must be true or false (got 'maybe')."),
    (["agent.latent_action_dim=abc"], "agent.latent_action_dim must be an integer or null (got 'abc')."),
    (["agent=iql", "offline.dataset=medium", "agent.iql.expectile=x"],
     "agent.iql.expectile must be a number (got 'x')."),
    # a task name no task file gives: was a traceback from the environment registry (dry run), and a sweep planned
    # runs of it
    (["task.name=cheeta_run"], "unknown task 'cheeta_run' in task.name (a task file of repro/conf/task/ names each "
                               "task). Did you mean: cheetah_run, walker_run?"),
])
def test_a_value_of_the_wrong_type_is_named_in_one_line(overrides, message):
    assert refusal(overrides) == message


def test_a_task_name_no_task_file_gives_is_refused_before_a_sweep_plans_it(tmp_path):
    from typer.testing import CliRunner

    from repro_app.cli import app

    out = CliRunner().invoke(app, ["sweep", "tiny", "--set", "task.name=foo", "--dry-run", "--results",
                                      str(tmp_path)], terminal_width=400)
    assert out.exit_code == 2 and out.output.startswith("error: unknown task 'foo' in task.name"), out.output
    assert len(out.output.strip().splitlines()) == 1 and not list(tmp_path.iterdir())


@pytest.mark.parametrize("overrides, message", [
    # drqv2's spelling of the schedule: was OmegaConf's "Invalid type assigned: str is not a subclass of StdSchedule"
    (["agent.stddev_schedule='linear(1.0,0.1,500000)'"],
     "agent.stddev_schedule is a section (start, end, duration, step_scale): set its values one by one, e.g. "
     "agent.stddev_schedule.start=... (got 'linear(1.0,0.1,500000)')."),
    (["train.seed_frames=-5"], "train.seed_frames must be >= 0 (got -5)."),  # were accepted
    (["train.explore_steps=-3"], "train.explore_steps must be >= 0 (got -3)."),
    (["train.checkpoint_every_episodes=0"],  # a ZeroDivisionError at the end of the first episode
     "train.checkpoint_every_episodes must be >= 1 (got 0)."),
    (["env.max_episode_frames=0"], "env.max_episode_frames must be >= 1 (got 0)."),
    (["agent.objectives=5"],  # was OmegaConf's "Cannot assign int to Dict[str, float]"
     "agent.objectives is a mapping: set its entries one by one, e.g. agent.objectives.<name>=... (got 5)."),
    (["runtime.results_root="],  # `runtime.results_root=$UNSET` in a script: the runs landed in the working folder
     "runtime.results_root is empty: name the folder the runs go under (default: runs)."),
])
def test_a_value_no_online_run_can_use_is_one_line(overrides, message):
    assert refusal(overrides) == message


def test_the_horizon_fits_the_episodes_the_replay_samples_from():
    """An online run's replay samples transitions with max(K, nstep) steps ahead in their episode: with episodes
    cut at env.max_episode_frames (profile=tiny: 50 agent steps) a longer horizon left nothing to sample, a traceback
    at the first update after the run directory was written. The check agrees with the replay's boundary."""
    import numpy as np

    from repro.config.compose import ConfigError, compose
    from repro.data.replay import ReplayBuffer

    assert compose(["profile=tiny", "agent.K=50"]).agent.K == 50
    with pytest.raises(ConfigError) as err:
        compose(["profile=tiny", "agent.K=51"])
    assert str(err.value) == ("agent.K=51 and agent.nstep=3 look further ahead than an episode of 50 agent steps "
                              "(env.max_episode_frames=100 / env.action_repeat=2): each must be <= 50.")
    with pytest.raises(ConfigError, match=r"^agent\.K=3 and agent\.nstep=51 look further ahead"):
        compose(["profile=tiny", "agent.nstep=51"])

    def valid_after_one_episode(capacity: int, nstep: int, K: int) -> int:
        """Transitions the replay can sample after one episode of 50 agent steps (the tiny profile's)."""
        buf = ReplayBuffer(capacity, (3, 4, 4), 2, frame_stack=3, nstep=nstep, K=K, discount=0.9, seed=0)
        buf.start_episode(np.zeros((3, 4, 4), np.uint8))
        for _ in range(50):
            buf.add(np.zeros(2, np.float32), reward=0.0, discount=1.0, next_frame=np.zeros((3, 4, 4), np.uint8))
        buf.end_episode()
        return buf.num_valid()

    for horizon, samples in ((50, True), (51, False)):
        valid = valid_after_one_episode(100, nstep=1, K=horizon)
        assert valid > 0 if samples else valid == 0
    with pytest.raises(ConfigError) as err:
        compose(["profile=tiny", "replay.capacity=5"])
    assert str(err.value) == ("replay.capacity=5 holds no transition 3 steps ahead (max(agent.K, agent.nstep)) "
                              "with its stack of 3 frames: it must be >= 6.")
    assert compose(["profile=tiny", "replay.capacity=6"]).replay.capacity == 6
    for capacity, samples in ((6, True), (5, False)):  # K = nstep = 3, three frames stacked, as the default
        valid = valid_after_one_episode(capacity, nstep=3, K=3)
        assert valid > 0 if samples else valid == 0


def test_a_run_holds_and_reads_its_own_learner_s_section_only():
    """A TACO run has no DT, CQL, IQL or TD3+BC section (issue 35): ``agent.dt.context=0`` is an unknown key there
    (as a plugin learner's would be), and one added with ``++`` (a sweep's override common to every agent) is dropped
    unread, unchecked; the DT run checks it."""
    from repro.config.compose import ConfigError, compose, run_keys

    base = compose(["agent=taco"])
    assert not {"cql", "td3bc", "iql", "dt"} & set(base.agent) and "toy_rwbc" not in base.agent
    with pytest.raises(ConfigError, match=r"^unknown config key 'agent\.dt\.context'\.") as err:
        compose(["agent=taco", "agent.dt.context=0"])
    assert "\n" not in str(err.value)
    dropped = compose(["agent=taco", "++agent.dt.context=0", "++agent.cql.n_samples=0"])
    assert run_keys(dropped) == run_keys(base)
    cql = compose(["agent=cql", "offline.dataset=medium", "++agent.dt.context=0"])
    assert "dt" not in cql.agent and cql.agent.cql.n_samples == 10
    with pytest.raises(ConfigError, match=r"^agent\.dt\.context must be >= 1 \(got 0\)\.$"):
        compose(["agent=dt", "offline.dataset=medium", "agent.dt.context=0"])


def test_no_generic_module_names_a_built_in_learner():
    """What a learner resolves from its config and data is its own hook (``LearnerSpec.resolve``: CQL's Table-6
    alpha; ``max_episode_length``: DT's timestep embedding): the modules every run goes through name no learner, as
    an attribute (``cfg.agent.cql``, ``LearnerName.cql``) or a string constant (``"cql_alpha"``, ``"dt"``)."""
    import ast
    from pathlib import Path

    names = {s.name for s in schema.BUILTIN_LEARNERS} - {"actor_critic"}
    names |= {f"{n}_{field}" for n in names for field in ("alpha", "max_timestep")}
    root = Path(schema.__file__).resolve().parents[1]
    for module in ("config/compose.py", "runs/rundir.py", "train/build.py", "train/api.py", "train/start.py"):
        tree = ast.parse((root / module).read_text(encoding="utf-8"))
        named = [(node.lineno, node.attr if isinstance(node, ast.Attribute) else node.value) for node in ast.walk(tree)
                 if isinstance(node, ast.Attribute) and node.attr in names
                 or isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names]
        assert not named, (module, named)


# ------------------------------------------------------------------------ every declared bound, read by one loop
def _declared_checks() -> list[tuple[str, typing.Any, typing.Any]]:
    """``(key, type, check)`` of every field that declares its allowed values in its annotation: the run config's,
    each built-in learner's own section (``agent.<learner>``), each built-in objective's parameters."""
    fields = [*declared(schema.RunConfig)]
    fields += [f for spec in schema.BUILTIN_LEARNERS if spec.section is not None
               for f in declared(spec.section, f"agent.{spec.name}.")]
    fields += [f for spec in schema.BUILTIN_OBJECTIVES if spec.params is not None
               for f in declared(spec.params, f"agent.objective_params.{spec.name}.")]
    return [(key, kind, check) for key, kind, check in fields if check is not None]


DECLARED = {key: (kind, check) for key, kind, check in _declared_checks()}


def _reading(key: str) -> tuple[list[str], str]:
    """Overrides choosing an agent file whose runs read ``key``, and the key as an override sets it (``+`` where the
    agent file does not hold it)."""
    from repro.config.compose import agent_learner, config_groups

    parts, agents = key.split("."), config_groups()["agent"]
    if parts[:2] == ["agent", "objective_params"]:
        if parts[2] in agents:  # spr.yaml, atc.yaml write their objective's parameters out
            return [f"agent={parts[2]}"], key
        return ["agent=taco", f"+agent.objectives.{parts[2]}=1.0"], f"+{key}"
    if parts[0] == "agent" and parts[1] in schema.learner_names():
        agent = next(a for a in agents if agent_learner(a) == parts[1])
        return [f"agent={agent}", *(["offline.dataset=medium"] if is_offline(parts[1]) else [])], key
    if parts[0] == "offline":
        return ["agent=bc", "offline.dataset=medium"], key
    return ["agent=taco"], key


def _outside(bound: Bound, number: type) -> list[typing.Any]:
    """A value just outside each limit the bound has."""
    values = [number(bound.ge - 1)] if bound.ge is not None else [number(bound.gt)] if bound.gt is not None else []
    values += [number(bound.le + 1)] if bound.le is not None else [number(bound.lt)] if bound.lt is not None else []
    values += [number(bound.low + 1)] if bound.even and bound.low is not None else []  # an odd number within
    return values + ([math.inf] if bound.finite else [])


@functools.cache
def _composed(agent: tuple[str, ...]) -> dict:
    """The config ``agent``'s overrides compose to, as plain containers (composed once per agent)."""
    from repro.config.compose import compose

    return OmegaConf.to_container(compose(list(agent)), resolve=True, enum_to_str=True)  # type: ignore[return-value]


def _validate_with(agent: list[str], setting: str, value: typing.Any) -> str | None:
    """The ConfigError line validating ``agent``'s config with ``setting`` (a key, ``+`` where the agent file lacks
    it) set to ``value``, as the override ``setting=value`` sets it; None when it validates."""
    from repro.config.compose import ConfigError, set_key, validate

    data = copy.deepcopy(_composed(tuple(agent)))
    set_key(data, setting.lstrip("+"), value)
    try:
        validate(OmegaConf.create(data))
    except ConfigError as err:
        return str(err)
    return None


@pytest.mark.parametrize("key", sorted(k for k, (_, check) in DECLARED.items() if isinstance(check, Bound)))
def test_every_declared_bound_refuses_a_value_outside_it_in_one_line_naming_key_and_bound(key: str):
    """Every bound declared in a field's annotation (one line beside the field: no table elsewhere) is checked, by
    the one loop of repro.config.compose: a value just outside each of its limits, set in the composed config of an
    agent whose runs read the key, as an override sets it, is one ConfigError line naming the key, the allowed values
    and the value; the limit itself, where it is allowed, is not refused by it. A field the loop missed fails here.
    (The tests above give such values as command-line overrides: one compose each, too slow for every bound.)"""
    kind, bound = DECLARED[key]
    agent, setting = _reading(key)
    if bound.each:  # a mapping (agent.objectives): each of its values is bounded
        setting, key = f"{setting}.taco", f"{key}.taco"
    plain = [a for a in (*typing.get_args(kind), kind) if a in (int, float)]
    number = plain[0] if plain else float
    values = _outside(bound, number)
    assert values, key
    for value in values:
        line = _validate_with(agent, setting, value)
        assert line is not None and line.startswith(f"{key} ") and bound.text() in line \
            and line.endswith(f"(got {value}).") and "\n" not in line, (key, value, line)
        if not (bound.even or bound.what or (isinstance(value, float) and math.isinf(value))):
            assert line == f"{key} must be {bound.text()} (got {value}).", line
    for edge in (bound.ge, bound.le):  # an inclusive limit is allowed (a bound is not off by one)
        if edge is not None:  # (a rule relating fields may refuse it, replay.capacity=1: not this bound)
            line = _validate_with(agent, setting, number(edge)) or ""
            assert not line.startswith((f"{key} must be", f"{key} is ")), (key, edge, line)


@pytest.mark.parametrize("key", sorted(k for k, (_, check) in DECLARED.items() if isinstance(check, Text)))
def test_every_declared_text_check_refuses_in_one_line(key: str):
    _, check = DECLARED[key]
    agent, setting = _reading(key)
    bad = "" if check.refusal(key, "a/b") is None else "a/b"
    assert refusal([*agent, f"{setting}={bad}"]) == check.says.format(key=key, value=bad)


# What was bounded before the bounds moved into the fields' annotations (issue 51): compose.py's RANGES, validate's
# inline ifs, _check_learner's list, the objectives' weights, the name checks and the registrations' ``ranges``.
BOUNDED_BEFORE = {
    *(f"agent.{k}" for k in ("K", "batch_size", "nstep", "stddev_schedule.step_scale", "feature_dim", "hidden_dim",
                             "action_hidden_dim", "latent_action_dim", "lr", "stddev_clip", "discount",
                             "critic_target_tau", "objectives", "name")),
    *(f"env.{k}" for k in ("action_repeat", "frame_stack", "image_size", "max_episode_frames", "distracting_dims")),
    *(f"train.{k}" for k in ("frames", "eval_every_frames", "update_every_steps", "seed_frames", "explore_steps",
                             "checkpoint_every_episodes", "eval_episodes", "video_size")),
    *(f"offline.{k}" for k in ("updates", "eval_every_updates", "checkpoint_every_updates", "log_every_updates",
                               "eval_episodes")),
    "replay.capacity", "seed", "experiment", "variant", "task.name", "runtime.results_root", "agent.td3bc.alpha",
    *(f"agent.cql.{k}" for k in ("alpha", "n_samples", "temperature")),
    *(f"agent.iql.{k}" for k in ("expectile", "beta", "max_weight", "actor_lr_cosine_updates")),
    *(f"agent.dt.{k}" for k in ("context", "embed_dim", "n_layers", "n_heads", "dropout", "lr", "weight_decay",
                                "warmup_steps", "grad_clip", "batch_size", "rtg_scale", "max_timestep")),
    *(f"agent.alix.{k}" for k in ("max_shift", "kernel", "target", "eps", "strength_init", "strength_lr",
                                  "strength_beta1", "strength_beta2", "input_shift")),
    *(f"agent.objective_params.{k}" for k in ("spr.momentum", "spr.projection_dim", "atc.momentum",
                                              "atc.predictor_hidden")),
}


def test_no_bound_was_lost_when_the_bounds_moved_into_the_fields():
    assert not BOUNDED_BEFORE - set(DECLARED), sorted(BOUNDED_BEFORE - set(DECLARED))


def test_a_bound_is_read_from_an_annotation_optional_outside_or_inside():
    from repro.config.bounds import check_in

    bound = Bound(ge=1)
    assert check_in(Annotated[typing.Optional[int], bound]) == bound
    assert check_in(typing.Optional[Annotated[int, bound]]) == bound
    assert check_in(typing.Optional[int]) is None and check_in(int) is None


def test_a_bound_added_by_one_line_in_a_field_s_annotation_is_enforced(monkeypatch):
    """A newcomer bounds a field by its annotation alone (here TD3+BC's alpha, given an upper limit): no table, no
    registration, no check elsewhere changes, and the run is refused in one line."""
    from repro.config import compose as compose_module

    overrides = ["agent=td3bc", "offline.dataset=medium", "agent.td3bc.alpha=11"]
    assert compose_module.compose(overrides).agent.td3bc.alpha == 11.0
    monkeypatch.setitem(schema.TD3BCConfig.__annotations__, "alpha", "Annotated[float, Bound(ge=0.0, le=10.0)]")
    compose_module._declared.cache_clear()
    try:
        assert refusal(overrides) == "agent.td3bc.alpha must be in [0.0, 10.0] (got 11.0)."
    finally:
        monkeypatch.undo()
        compose_module._declared.cache_clear()


def test_no_bound_is_declared_outside_the_fields():
    """The ranges tables, the specs' bound tuples and the hand lists are gone: a registration carries no bound, and
    compose.py names no bound table."""
    from repro.config import compose as compose_module
    from repro.config.plugins import LearnerSpec, ObjectiveSpec

    assert not {"ranges"} & {f.name for kind in (LearnerSpec, ObjectiveSpec) for f in dataclasses.fields(kind)}
    assert not hasattr(compose_module, "RANGES") and not hasattr(compose_module, "FINITE")
    assert not hasattr(schema, "registered_ranges")


def test_the_config_layer_reads_omegaconf_through_its_public_api():
    """No private attribute of another object (OmegaConf's node API: ``_metadata``, ``_get_node()``, ``_value()``,
    ``_is_missing()``) and no private name imported, in repro/config/."""
    import ast
    from pathlib import Path

    found = []
    for path in sorted((Path(schema.__file__).resolve().parent).glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__") \
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                found.append(f"{path.name}:{node.lineno} {ast.unparse(node)}")
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] != "repro":
                private = [a.name for a in node.names if a.name.startswith("_")]
                if private or any(part.startswith("_") and not part.startswith("__")
                                  for part in (node.module or "").split(".")):
                    found.append(f"{path.name}:{node.lineno} from {node.module} import {private}")
    assert not found, found


def test_every_yaml_value_in_repro_conf_is_commented():
    """Every ``key: value`` line of the packaged YAML (the values' one source) says what the value is."""
    from repro.config.compose import CONF_DIR

    bare = []
    for path in sorted(CONF_DIR.rglob("*.yaml")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            key, sep, value = line.partition(":")
            if sep and value.strip() and not line.lstrip().startswith(("#", "-")) and "#" not in line:
                bare.append(f"{path.relative_to(CONF_DIR)}:{number}: {line.strip()}")
    assert not bare, bare
