"""The open registries (issue 25) through the worked example of docs/extending.md: tests/plugin_example, the package
``taco-repro-toy`` installed as a user would (``pip install -e tests/plugin_example``; ``make test`` does it). It
registers a learner (``toy_rwbc``) and an objective (``toy_inv``) through the entry-point groups; nothing in the
tree names them, and each is first-class: config, train, sweep, status, bench, tables."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import itertools
import math
import re
from pathlib import Path
from typing import Annotated

import pandas as pd
import pytest
import torch
import yaml
from typer.testing import CliRunner

from analysis.identity import agent_labels, method_label
from analysis.load import load_results
from analysis.scores import final_scores
from analysis.tables import to_markdown
from helpers import REPRO, bench_app, host_syncs, launch_app
from offline_fixtures import write_dataset
from repro.config.compose import (
    ConfigError,
    agent_learner,
    compose,
    config_groups,
    offline_agents,
    online_agents,
    run_keys,
    typed,
)
from repro.config.plugins import Bound, LearnerSpec, PluginError, check_spec, discover, load_factory
from repro.config.schema import is_offline, learner_names, objective_names, unread_keys
from repro.learners import build_learner
from repro.runs import rundir
from repro.train import api

try:
    TOY = importlib.metadata.distribution("taco-repro-toy")
except importlib.metadata.PackageNotFoundError:  # the suite needs it: say how to install it, once
    raise RuntimeError("tests/test_plugins.py needs the example plugin: pip install -e tests/plugin_example "
                       "(make test installs it)") from None

TINY = ["task=cheetah_run", "profile=tiny", "env.image_size=32", "agent.feature_dim=16", "agent.hidden_dim=16",
        "runtime.threads=1", "env.max_episode_frames=20"]  # 10-step episodes: rendering is most of the time
OFFLINE = ["offline.dataset=medium", "offline.updates=4", "offline.eval_every_updates=4", "offline.eval_episodes=1",
           "offline.checkpoint_every_updates=4", "offline.log_every_updates=2"]


def test_the_example_registers_through_its_entry_points_only():
    groups = {(ep.group, ep.name) for ep in TOY.entry_points}
    assert groups == {("taco_repro.learners", "toy_rwbc"), ("taco_repro.learners", "toy_utd"),
                      ("taco_repro.objectives", "toy_inv")}
    assert "toy_rwbc" in learner_names() and is_offline("toy_rwbc") and "toy_inv" in objective_names()
    assert "toy_utd" in learner_names() and not is_offline("toy_utd")
    assert {"toy_rwbc", "toy_utd", "toy_inv"} <= set(config_groups()["agent"])  # its conf folder is on the search path
    # the bench list: the built-in offline agent files in the paper's order, then the plugin's
    assert offline_agents() == ("bc", "td3bc", "td3bc_taco", "cql", "cql_taco", "iql", "dt", "toy_rwbc")
    assert {"taco", "drqv2", "toy_inv", "toy_utd"} <= set(online_agents())  # `repro bench update --agent`'s choices
    assert not set(online_agents()) & set(offline_agents())
    labels = agent_labels()
    assert (labels["toyrwbc"], labels["toyutd"], labels["toyinv"]) == ("RWBC", "DrQ-v2-UTD", "InvDyn")
    assert method_label("toy_rwbc", ("taco", "curl", "reward")) == "RWBC+TACO"  # with TACO, as CQL+TACO
    assert method_label("toy_rwbc", ("toy_inv",)) == "RWBC+InvDyn"
    root = Path(__file__).resolve().parent
    assert not [p for p in (root.parent / "repro").rglob("*.py") if "toy_rwbc" in p.read_text() or "toy_utd" in
                p.read_text()]


def test_distinct_learner_and_objectives_never_share_a_label():
    """Every registered learner (the plugin's included) with every set of registered objectives: one label each,
    from the registry; the paper's methods keep the paper's labels."""
    objectives = list(objective_names())
    labels: dict[str, tuple[str, tuple[str, ...]]] = {}
    for learner in learner_names():
        for n in range(len(objectives) + 1):
            for chosen in itertools.combinations(objectives, n):
                label = method_label(learner, chosen)
                assert label not in labels, (label, labels.get(label), (learner, chosen))
                labels[label] = (learner, chosen)
    bundle = ("taco", "curl", "reward")
    assert [method_label("actor_critic", o) for o in [(), bundle, ("curl",), ("spr", "curl", "reward"),
                                                      ("atc", "curl", "reward"), ("driml", "curl", "reward")]] == \
        ["DrQ-v2", "TACO", "CURL", "SPR", "ATC", "DRIML"]
    assert [method_label(learner, bundle) for learner in ("cql", "td3bc", "bc")] == ["CQL+TACO", "TD3+BC+TACO",
                                                                                     "BC+TACO"]
    assert method_label("cql", ("spr", "curl", "reward")) == "CQL+SPR" != method_label("cql") == "CQL"
    assert method_label("actor_critic", ("taco", "reward")) == "TACO w/o CURL"  # objective_removal's no_curl
    assert method_label("actor_critic", ("curl", "reward")) == "CURL+Reward"  # and its no_taco
    assert method_label("toy_utd", bundle) == "DrQ-v2-UTD+TACO"
    assert method_label("actor_critic", ["toy_inv"]) == "InvDyn"


def test_runs_of_two_methods_never_share_a_table_cell(tmp_path):
    """The bug of issue 35: an offline learner trained with an objective other than TACO was labelled as the plain
    learner and averaged into its cells. Runs of CQL, CQL+SPR and CQL+TACO on one task, dataset and experiment (the
    variant apart) are three methods: three cells of a table grouped by method."""
    from analysis_fixtures import write_run

    for variant, objectives, final in (("plain", {}, 100.0), ("spr", {"spr": 1.0, "curl": 1.0, "reward": 1.0}, 200.0),
                                       ("taco", {"taco": 1.0, "curl": 1.0, "reward": 1.0}, 300.0)):
        write_run(tmp_path, experiment="offline", agent="cql", variant=variant, task="hopper_hop", dataset="medium",
                  seed=1, final=final, objectives=objectives, action_encoder=bool(objectives))
    cells = final_scores(load_results(tmp_path)).groupby(["task", "dataset", "method"])["score"].agg(["count", "mean"])
    assert sorted(cells.index.get_level_values("method")) == ["CQL", "CQL+SPR", "CQL+TACO"]
    assert cells["count"].tolist() == [1, 1, 1]


def test_a_registered_label_is_its_own_and_companions_are_registered(monkeypatch):
    """A plugin that registers a label already taken (it would name two methods alike) or a companion nobody
    registers is one line."""
    import repro.config.schema as schema
    from repro.config.plugins import ObjectiveSpec

    for spec, message in ((ObjectiveSpec("toy_inv", label="CQL", factory="m:a"), "label 'CQL' is already the label of "
                                                                                 "learner 'cql'"),
                          (ObjectiveSpec("toy_inv", label="X", factory="m:a", companions=("nope",)),
                           "companion 'nope' must be another registered objective")):
        monkeypatch.setattr(schema, "discover", lambda group, kind, spec=spec: (spec,) if kind is ObjectiveSpec else
                            discover(group, kind))
        schema.objective_specs.cache_clear()
        try:
            with pytest.raises(PluginError, match=re.escape(message)):
                schema.objective_specs()
        finally:
            schema.objective_specs.cache_clear()


def test_docs_extending_states_the_files_a_plugin_method_costs():
    """docs/extending.md's table counts the example's files: those that name the method or hold its code. A file the
    method needs and the table does not count (a section YAML of its own, say) names it, and fails here."""
    root = Path(__file__).resolve().parent
    example = root / "plugin_example"
    costs = {"toy_rwbc": ["pyproject.toml", "taco_repro_toy/__init__.py", "taco_repro_toy/learner.py",
                          "taco_repro_toy/losses.py", "taco_repro_toy/conf/agent/toy_rwbc.yaml"],
             "toy_inv": ["pyproject.toml", "taco_repro_toy/__init__.py", "taco_repro_toy/objective.py",
                         "taco_repro_toy/losses.py", "taco_repro_toy/conf/agent/toy_inv.yaml"]}
    code = {"toy_rwbc": ("RWBC", "return_weights", "weighted_bc_loss"),
            "toy_inv": ("InverseDynamics", "inverse_dynamics_loss")}
    files = [p for p in example.rglob("*") if p.is_file() and p.suffix in (".py", ".toml", ".yaml")]
    for method, listed in costs.items():
        naming = sorted(str(p.relative_to(example)) for p in files
                        if any(word in p.read_text() for word in (method, *code[method])))
        assert naming == sorted(listed), (method, naming)
    table = (root.parent / "docs" / "extending.md").read_text()
    assert f"| an offline (or online) learner | {len(costs['toy_rwbc'])} files:" in table
    assert f"| an auxiliary objective | {len(costs['toy_inv'])} files:" in table


def test_the_update_bench_times_the_online_plugin_learner(tmp_path):
    """`repro bench update --agent toy_utd`: the plugin's online learner is built through the registry and timed."""
    args = ["bench", "update", "--agent", "toy_utd", "--batch", "2", "--repeats", "1", "--warmup", "0", "--results",
            str(tmp_path)]
    result = CliRunner().invoke(bench_app(), args)
    assert result.exit_code == 0, result.output
    assert "toy_utd batch     2: " in result.output and "s/update" in result.output
    report = yaml.safe_load(next((tmp_path / "bench").glob("bench-*-cpu.json")).read_text())
    assert [(r["agent"], r["batch_size"]) for r in report["results"]] == [("toy_utd", 2)]


def test_the_light_agent_file_reading_agrees_with_hydra():
    """offline_agents reads each agent file's learner from YAML (inherited files followed); Hydra composes it."""
    for agent in config_groups()["agent"]:
        learner = agent_learner(agent)
        if agent in ("taco", "drqv2", "spr", "td3bc_taco", "cql_taco", "toy_inv", "toy_rwbc", "toy_utd"):  # each once
            over = ["offline.dataset=medium"] if is_offline(learner) else []
            assert str(compose([f"agent={agent}", *over]).agent.learner) == learner, agent


def test_a_plugin_learner_s_section_is_typed_and_held_by_its_runs_only():
    cfg = compose(["agent=toy_rwbc", "offline.dataset=medium", "agent.toy_rwbc.temperature=0.5"])
    section = typed(cfg).agent.toy_rwbc  # type: ignore[attr-defined]
    assert type(section).__name__ == "RWBCConfig" and section.temperature == 0.5
    assert run_keys(cfg)["agent"]["toy_rwbc"] == {"temperature": 0.5, "max_weight": 20.0}
    assert "toy_rwbc" not in run_keys(compose(["agent=cql", "offline.dataset=medium"]))["agent"]
    assert "agent.toy_rwbc" in unread_keys("cql") and "agent.cql" in unread_keys("toy_rwbc")
    with pytest.raises(ConfigError, match=r"^agent\.toy_rwbc\.temperature must be a number \(got 'hot'\)\.$") as err:
        compose(["agent=toy_rwbc", "offline.dataset=medium", "agent.toy_rwbc.temperature=hot"])
    assert "\n" not in str(err.value)


def test_a_misspelt_key_of_a_plugin_learner_s_section_names_its_keys():
    """The suggestions come from the plugin's agent file (its learner's section), not the default agent's."""
    with pytest.raises(ConfigError) as err:
        compose(["agent=toy_rwbc", "offline.dataset=medium", "agent.toy_rwbc.temprature=2"])
    assert str(err.value) == "unknown config key 'agent.toy_rwbc.temprature'. Did you mean: temperature?"


@pytest.mark.parametrize("override, message", [
    ("agent.learner=toy_rwbcc",
     "agent.learner=toy_rwbcc is not one of actor_critic, bc, td3bc, cql, iql, dt, alix, toy_rwbc, toy_utd."),
    ("+agent.objectives.toy_invv=1", "unknown objective 'toy_invv' in agent.objectives. Did you mean: toy_inv? "
                                     "Registered objectives: taco, curl, reward, spr, atc, driml, toy_inv."),
    ("agent.objectives.foo=1", "unknown objective 'foo' in agent.objectives. Registered objectives: taco, curl, "
                               "reward, spr, atc, driml, toy_inv."),
    # the objective's parameters, typed by its registered params (InvParams): issue 37
    ("agent.objective_params.toy_inv.hidden_dim=abc",
     "agent.objective_params.toy_inv.hidden_dim must be an integer or null (got 'abc')."),
    ("agent.objective_params.toy_inv.hidden_dim=4.7",  # was truncated to 4
     "agent.objective_params.toy_inv.hidden_dim must be an integer or null (got 4.7)."),
    ("+agent.objective_params.toy_inv.hiden_dim=4",  # was a traceback from the objective's __init__
     "unknown setting agent.objective_params.toy_inv.hiden_dim of objective 'toy_inv'. Did you mean: hidden_dim?"),
])
def test_a_misspelled_registered_name_is_one_line_and_exit_2(tmp_path, override: str, message: str):
    from repro_app.cli import app

    for dry_run in (["--dry-run"], []):
        out = CliRunner().invoke(app, ["train", *dry_run, "agent=toy_inv", override,
                                       f"runtime.results_root={tmp_path}"], terminal_width=400)
        assert out.exit_code == 2 and message in out.output and len(out.output.strip().splitlines()) == 1, out.output
    assert not list(tmp_path.iterdir())


def test_an_objective_reads_its_registered_params_typed():
    from taco_repro_toy import InvParams

    from repro.config.compose import objective_params
    from repro.config.plugins import ObjectiveSpec

    assert objective_params("toy_inv", {"hidden_dim": 8}) == InvParams(hidden_dim=8)
    rc = typed(compose(["agent=toy_inv", "task=cheetah_run", "profile=tiny",
                        "agent.objective_params.toy_inv.hidden_dim=8"]))
    assert build_learner(rc.agent, (9, 84, 84), 6, "cpu").backbone.objectives["toy_inv"].head[0].out_features == 8
    for params, message in ((dict, "params must be a dataclass"), (RWBCFields, "must give every field a default")):
        spec = ObjectiveSpec("toy_x", factory="m:a", params=params)
        with pytest.raises(PluginError, match=re.escape(message)):
            check_spec(spec, "toy_x")


@dataclasses.dataclass
class RWBCFields:
    """A params dataclass without defaults (refused: an objective's parameters are optional in a config)."""

    hidden_dim: int


@pytest.mark.parametrize("agent, override, message", [
    ("toy_rwbc", "agent.toy_rwbc.temperature=0", "agent.toy_rwbc.temperature must be > 0.0 (got 0.0)."),
    ("toy_rwbc", "agent.toy_rwbc.max_weight=0.5", "agent.toy_rwbc.max_weight must be >= 1.0 (got 0.5)."),
    ("toy_inv", "agent.objective_params.toy_inv.hidden_dim=0",
     "agent.objective_params.toy_inv.hidden_dim must be >= 1 (got 0)."),
])
def test_a_plugin_setting_out_of_its_registered_range_is_one_line_and_exit_2(tmp_path, agent: str, override: str,
                                                                             message: str):
    from repro_app.cli import app

    dataset = ["offline.dataset=medium"] if agent == "toy_rwbc" else []
    tiny = [*TINY, "train.frames=40", "train.eval_episodes=0", "train.save_frames=false"]  # were it to train
    out = CliRunner().invoke(app, ["train", f"agent={agent}", *dataset, *tiny, override,
                                   f"runtime.results_root={tmp_path}"])
    assert out.exit_code == 2 and message in out.output and len(out.output.strip().splitlines()) == 1, out.output
    assert not list(tmp_path.iterdir())
    # the bounds themselves are allowed (a range is not off by one), and null is not checked
    edge = {"toy_rwbc": ["agent.toy_rwbc.temperature=1e-9", "agent.toy_rwbc.max_weight=1"],
            "toy_inv": ["agent.objective_params.toy_inv.hidden_dim=1"]}[agent]
    compose([f"agent={agent}", *dataset, *edge])
    compose(["agent=toy_inv", "agent.objective_params.toy_inv.hidden_dim=null"])


@pytest.mark.parametrize("limits, message", [
    ({"ge": 1.0, "le": 0.5}, "Bound: the lower limit 1.0 is above the upper limit 0.5."),
    ({"ge": 0.0, "gt": 0.0}, "Bound: give one lower limit (ge or gt) and one upper limit (le or lt) at most."),
    ({"gt": "0"}, "Bound: gt must be a number (got '0')."),
    ({}, "Bound: give a limit (ge, gt, le or lt), finite or even."),
])
def test_an_unusable_bound_is_a_one_line_error_where_it_is_declared(limits, message: str):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        Bound(**limits)


def test_a_bound_on_a_field_that_holds_no_number_is_a_one_line_registration_error():
    @dataclasses.dataclass
    class Section:
        temperature: Annotated[str, Bound(gt=0.0)]

    spec = LearnerSpec("toy_x", offline=True, label="X", section=Section, factory="m:a")
    with pytest.raises(PluginError, match=re.escape("toy_x: section Section: field 'temperature' has a bound but is "
                                                    "str, not a number.")):
        check_spec(spec, "toy_x")


def test_a_broken_registration_is_one_line(monkeypatch):
    class EntryPoint:
        name, group, value = "other", "taco_repro.learners", "taco_repro_toy:LEARNER"

        def load(self) -> LearnerSpec:
            return LearnerSpec("toy_rwbc", offline=True, label="X", factory="m:a")

    monkeypatch.setattr("repro.config.plugins.entry_points", lambda group: [EntryPoint()])
    with pytest.raises(PluginError, match="registers 'toy_rwbc' under the entry-point name 'other'"):
        discover("taco_repro.learners", LearnerSpec)
    with pytest.raises(PluginError, match=r"^'gone': cannot import its factory taco_repro_toy\.nope:Gone: "
                                          "ModuleNotFoundError") as err:
        load_factory(LearnerSpec("gone", offline=True, label="Gone", factory="taco_repro_toy.nope:Gone"))
    assert "\n" not in str(err.value)


def test_the_toy_learner_weights_bc_by_return_and_returns_detached_scalars():
    torch.manual_seed(0)
    learner = build_learner(typed(compose(["agent=toy_rwbc", *TINY, "offline.dataset=medium"])).agent, (9, 32, 32), 6,
                            "cpu")
    g = torch.Generator().manual_seed(0)
    batch = {"obs": torch.randint(0, 256, (4, 9, 32, 32), generator=g, dtype=torch.uint8),
             "action": torch.rand(4, 6, generator=g) * 2 - 1, "reward": torch.tensor([0.0, 1.0, 2.0, 3.0])}
    metrics = learner.update(batch, 0)
    assert set(metrics) == set(learner.metric_names())
    assert all(isinstance(v, torch.Tensor) and v.dim() == 0 and not v.requires_grad for v in metrics.values())
    # exp((r - 3) / 1) normalised to mean 1: the best transition weighs most
    w = torch.exp(torch.tensor([0.0, 1.0, 2.0, 3.0]) - 3.0)
    assert float(metrics["rwbc_max_weight"]) == pytest.approx(float((w / w.mean()).max()))


def test_the_toy_online_learner_takes_its_critic_steps_then_one_actor_step(monkeypatch):
    """toy_utd's update: critic_steps steps of the critic (and the encoder) for one of the actor, DrQ-v2's metric
    columns as detached 0-d tensors without a host sync; with critic_steps 1 it is the built-in DrQ-v2 update,
    bit for bit."""
    batch = _batch()
    learners = {}
    for agent, over in (("toy_utd", ["agent.toy_utd.critic_steps=3"]), ("toy_utd", ["agent.toy_utd.critic_steps=1"]),
                        ("drqv2", [])):
        torch.manual_seed(0)
        learner = build_learner(typed(compose([f"agent={agent}", *TINY, *over])).agent, (9, 32, 32), 6, "cpu")
        learners[agent + "".join(over)[-1:]] = (learner, learner.update(batch, 0))
    utd, metrics = learners["toy_utd3"]
    import taco_repro_toy

    with host_syncs(monkeypatch, (REPRO, str(Path(taco_repro_toy.__file__).parent))) as syncs:
        utd.update(batch, 1)  # the tree's backbone and the plugin's own code
    assert not syncs, syncs
    steps = {k: int(opt.state_dict()["state"][0]["step"]) for k, opt in utd.optimizers().items()}
    assert steps == {"encoder": 6, "critic": 6, "actor": 2}  # two updates
    assert sorted(metrics) == sorted(utd.metric_names())
    assert all(isinstance(v, torch.Tensor) and v.dim() == 0 and not v.requires_grad for v in metrics.values())
    (one, m1), (drqv2, m2) = learners["toy_utd1"], learners["drqv2"]
    assert {k: v.item() for k, v in m1.items()} == {k: v.item() for k, v in m2.items()}
    assert all(torch.equal(a, b) for a, b in zip(one.backbone.critic.state_dict().values(),
                                                 drqv2.backbone.critic.state_dict().values()))


def _batch(B: int = 4, K: int = 3) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    frames = lambda *lead: torch.randint(0, 256, (*lead, 9, 32, 32), generator=g, dtype=torch.uint8)  # noqa: E731
    return {"obs": frames(B), "next_obs": frames(B), "future_obs": frames(B), "future_obs_seq": frames(B, K),
            "action": torch.rand(B, 6, generator=g) * 2 - 1, "action_seq": torch.rand(B, K, 6, generator=g) * 2 - 1,
            "reward": torch.rand(B, 1, generator=g), "discount": torch.full((B, 1), 0.97)}


@pytest.mark.slow
def test_each_toy_method_trains_tiny_is_a_sweep_s_run_and_shows_its_label(tmp_path, monkeypatch):
    """The offline learner through `repro sweep` and `repro status`, the objective through `repro train`'s API,
    the online learner through `repro train`;
    the analysis table of their run directories, `repro report` and `repro plot` show each one's registered
    label."""
    root = tmp_path / "runs"
    write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6,
                  frame_shape=(3, 32, 32), best_return=200.0)
    sweep = tmp_path / "toy.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "toy", "description": "the plugin's learner", "artifacts": [], "experiment": "toy",
        "tasks": ["cheetah_run"], "agents": ["toy_rwbc"], "seeds": 1, "frames": None,
        "eval": {"every_frames": None, "episodes": None},
        "common": [o for o in TINY if o != "task=cheetah_run"] + OFFLINE, "variants": {"base": []}}))
    runner, app = CliRunner(), launch_app()
    out = runner.invoke(app, ["sweep", str(sweep), "--results-root", str(root)])
    assert out.exit_code == 0, out.output
    status = runner.invoke(app, ["status", "toy", "--results-root", str(root)])
    assert status.exit_code == 0 and "1 done" in status.output, status.output
    online = [*TINY, f"runtime.results_root={root}", "experiment=toy", "train.frames=40", "train.seed_frames=20",
              "train.explore_steps=10", "train.eval_every_frames=40", "train.eval_episodes=1",
              "train.save_frames=false"]
    objective = api.train([*online, "agent=toy_inv"], echo=lambda s: None)
    from repro_app.cli import app as cli  # the online learner through `repro train`

    out = runner.invoke(cli, ["train", "agent=toy_utd", *online, "--no-progress"])
    assert out.exit_code == 0, out.output
    runs = {yaml.safe_load(p.read_text())["agent"]["name"]: p.parent for p in root.rglob(rundir.CONFIG)}
    assert set(runs) == {"toy_rwbc", "toy_inv", "toy_utd"} and runs["toy_inv"] == objective
    for run, columns in ((runs["toy_rwbc"], ["rwbc_loss"]), (runs["toy_inv"], ["toy_inv_loss"]),
                         (runs["toy_utd"], ["critic_loss", "critic_target_q", "actor_loss", "actor_ent"])):
        train = pd.read_csv(run / "train.csv")
        for column in columns:
            values = train[column].dropna()  # online: no update before train.seed_frames
            assert len(values) and all(math.isfinite(float(v)) for v in values), (run, column)
    assert yaml.safe_load((runs["toy_utd"] / rundir.CONFIG).read_text())["agent"]["toy_utd"] == {"critic_steps": 2}
    table = to_markdown(final_scores(load_results(root))[["method", "task", "seed", "score"]])
    assert "| RWBC " in table and "| InvDyn " in table and "| DrQ-v2-UTD " in table, table
    _report_and_plot_name_the_labels(root, tmp_path, monkeypatch)


def _report_and_plot_name_the_labels(root: Path, tmp_path: Path, monkeypatch) -> None:
    """`repro report` end to end on the plugin runs (read as the paper's online and offline experiments, at their
    own tiny budget): Table 1 has the objective's and the online learner's rows and Table 3 the offline learner's,
    by their labels, each from its one run; `repro plot` draws the three runs' curves under those labels."""
    import paper_figures.quick_plot
    import repro_app.report
    from repro_app.cli import app

    runner = CliRunner()
    monkeypatch.setattr(repro_app.report, "REPORT_SIMS", 20)  # the power section's draws: its numbers are not read
    out = runner.invoke(app, ["report", "-r", str(root), "-o", str(tmp_path / "report"), "--frames", "40",
                              "-x", "main=toy", "-x", "offline=toy", "--reps", "50", "--tsne-n", "5",
                              "--no-render-envs", "--no-published"])
    assert out.exit_code == 0 and "Loaded 3 runs (3 done)" in out.output, out.output
    t1 = pd.read_csv(tmp_path / "report" / "T1.csv").set_index(["task", "method"])
    t3 = pd.read_csv(tmp_path / "report" / "T3.csv").set_index(["task", "dataset", "method"])
    assert t1.loc[("cheetah_run", "InvDyn"), "n"] == t1.loc[("cheetah_run", "DrQ-v2-UTD"), "n"] == 1
    assert t3.loc[("cheetah_run", "medium", "RWBC"), "n"] == 1
    report = (tmp_path / "report" / "REPORT.md").read_text()
    t1_md, t3_md = (report.split(f"## {t}:")[1].split("\n## ")[0] for t in ("T1", "T3"))
    assert "| InvDyn |" in t1_md and "| DrQ-v2-UTD |" in t1_md and "| RWBC |" in t3_md
    drawn: list[str] = []
    real = paper_figures.quick_plot.plot_curves
    monkeypatch.setattr(paper_figures.quick_plot, "plot_curves",
                        lambda curves, *a, **kw: drawn.extend(curves["label"]) or real(curves, *a, **kw))
    out = runner.invoke(app, ["plot", str(root), "--by", "method", "-o", str(tmp_path / "curves.png"), "--reps", "20",
                              "--no-published"])
    assert out.exit_code == 0 and "3 run(s), 1 task(s)" in out.output and (tmp_path / "curves.png").stat().st_size
    assert set(drawn) == {"RWBC", "InvDyn", "DrQ-v2-UTD"}


def test_the_paper_s_offline_sweeps_list_every_packaged_offline_agent_file_and_no_plugin_s():
    """A learner added to the tree without its agent files in the two offline sweeps fails here; a plugin's learner
    goes in a sweep file of its own (it is not the paper's)."""
    from repro.config.compose import CONF_DIR
    from repro.launch import spec as specs

    packaged = {a for a in offline_agents() if (CONF_DIR / "agent" / f"{a}.yaml").is_file()}
    assert "toy_rwbc" not in packaged and {"bc", "cql", "dt"} <= packaged
    for sweep in ("offline", "tiny_offline"):
        assert set(specs.load(sweep).agents) == packaged, sweep
