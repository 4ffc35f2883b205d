"""The trainer -> analysis contract (repro/runs/runformat.py): a real run loads through analysis with every identity
and resolved field equal to what the config says and what the trained networks show; runs written before
resolved.json existed fall back to their config, marked, never to a formula; fixtures obey the schema."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import torch
from omegaconf.errors import ConfigAttributeError

from analysis import select
from analysis.context import Context
from analysis.load import IDENTITY, load_results
from analysis_fixtures import FRAMES, run_config, write_run
from paper_figures import f10_action_dim
from repro.config.compose import compose, typed
from repro.envs import get_task
from repro.runs import rundir, runformat
from repro.train import api, build

# its module-scoped runs are made once: every test of this module on one pytest-xdist worker
pytestmark = pytest.mark.xdist_group("contract")

# hopper_hop: |A| = 4, so upstream's int(1.25|A|) + 1 = 6 differs from the paper's ceil(1.25|A|) = 5.
OVERRIDES = ["profile=tiny", "task=hopper_hop", "experiment=contract", "variant=v1", "seed=5", "agent.K=2",
             "env.action_repeat=4", "train.frames=200", "train.eval_every_frames=200", "train.save_frames=false",
             "runtime.threads=1"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("results")
    return root, api.train([*OVERRIDES, f"runtime.results_root={root}"], echo=lambda s: None)


@pytest.mark.slow
def test_real_run_loads_with_every_field_it_used(trained):
    root, run = trained
    cfg = compose([*OVERRIDES, f"runtime.results_root={root}"])
    rc = typed(cfg)
    for name in (runformat.CONFIG, runformat.META, runformat.RESOLVED, runformat.EVAL, runformat.TRAIN,
                 runformat.CHECKPOINT, runformat.DONE):
        assert (run / name).is_file(), name
    # what the trained networks show: latent dim and K from the action encoder's weights, active objectives
    modules = torch.load(run / runformat.CHECKPOINT, weights_only=True)["agent"]
    latent = modules["action_encoder"]["step.2.weight"].shape[0]
    k_used = modules["action_encoder"]["seq.0.weight"].shape[0] // latent
    objectives = sorted(m.removeprefix("objective.") for m in modules if m.startswith("objective."))
    assert latent == 6 and k_used == 2 and objectives == ["curl", "reward", "taco"]
    header = (run / runformat.TRAIN).read_text().splitlines()[0].split(",")
    assert header[:len(runformat.TRAIN_COLUMNS)] == list(runformat.TRAIN_COLUMNS)
    assert (run / runformat.EVAL).read_text().splitlines()[0].split(",") == list(runformat.EVAL_COLUMNS)

    res = load_results(root)
    assert [p for p in res.problems if p.path.startswith(str(run))] == []
    assert len(res.runs) == 1
    row = res.runs.iloc[0]
    expected = {
        "run_id": str(run.relative_to(root)), "experiment": "contract", "variant": "v1", "agent": "taco",
        "method": "TACO", "task": "hopper_hop", "suite": rc.task.suite, "seed": 5, "learner": "actor_critic",
        "K": k_used, "batch_size": rc.agent.batch_size, "nstep": rc.agent.nstep, "latent_action_dim": latent,
        "action_encoder": True, "objectives": "+".join(objectives), "action_repeat": 4,
        "distracting_dims": rc.env.distracting_dims, "max_episode_frames": 100, "camera": None,  # profile=tiny's
        "train_frames": 200, "dataset": None, "cql_alpha": None,
        "offline_updates": None, "status": runformat.STATE_DONE,
    }
    assert set(expected) == set(IDENTITY)  # every identity column the loader produces is checked here
    got = {k: (None if not isinstance(row[k], str) and pd.isna(row[k]) else row[k]) for k in IDENTITY}
    assert got == expected
    assert row["resolved_from"] == runformat.RESOLVED
    assert select.dim_value(row) == 6  # the dimension the run used, not ceil(1.25 |A|) = 5

    resolved = json.loads((run / runformat.RESOLVED).read_text())
    assert resolved["objectives"] == {"taco": 1.0, "curl": 1.0, "reward": 1.0}
    ev = pd.read_csv(run / runformat.EVAL)
    assert list(ev["frame"]) == [0, 200] and list(ev["frame"]) == list(ev["step"] * 4)
    loaded = res.eval.sort_values("frame")
    assert list(loaded["frame"]) == list(ev["frame"])
    assert list(loaded["episode_reward"]) == pytest.approx(list(ev["episode_reward"]))
    assert set(loaded["run_id"]) == {expected["run_id"]}


def test_f10_places_a_default_dim_run_at_the_dim_its_agent_used(tmp_path):
    """A real Agent for quadruped_run with latent_action_dim unset; F10 must show it at 16 (upstream rounding)."""
    cfg = run_config("taco", "quadruped_run", 0, tmp_path, experiment="action_dim", variant="dimdefault",
                     **{"train.frames": FRAMES})
    rc = typed(cfg)
    assert rc.agent.latent_action_dim is None and rc.agent.latent_action_rounding == "upstream"
    agent = build.build_run_learner(rc, (9, 84, 84), get_task("quadruped_run").action_dim, "cpu")
    values = rundir.resolved_values(rc, agent)
    assert values["latent_action_dim"] == 16 == agent.action_encoder.latent_dim
    write_run(tmp_path, experiment="action_dim", agent="taco", task="quadruped_run", seed=0, final=420.0,
              variant="dimdefault", resolved_values=values)
    write_run(tmp_path, experiment="action_dim", agent="taco", task="quadruped_run", seed=0, final=300.0,
              variant="dim6", latent_action_dim=6)
    ctx = Context(results=load_results(tmp_path), out_dir=tmp_path / "out", budget=FRAMES, reps=50)
    dims = select.action_dim_runs(ctx.scores).set_index("variant")["dim"]
    assert dims.to_dict() == {"dimdefault": 16, "dim6": 6}
    f10_action_dim.render(ctx)
    table = pd.read_csv(ctx.out_dir / "F10.csv")
    ran = table[table["repro_mean"].notna()].set_index("dim")["repro_mean"]
    assert ran.to_dict() == {6: pytest.approx(300.0), 16: pytest.approx(420.0)}


def test_run_without_resolved_values_falls_back_to_its_config_marked(tmp_path):
    old = write_run(tmp_path, experiment="action_dim", agent="taco", task="quadruped_run", seed=0, final=1.0,
                    K=2, resolved=False)
    write_run(tmp_path, experiment="action_dim", agent="taco", task="quadruped_run", seed=1, final=1.0,
              latent_action_dim=12, resolved=False)
    res = load_results(tmp_path)
    warnings = [p for p in res.problems if p.path == str(old / runformat.RESOLVED)]
    assert len(warnings) == 1 and warnings[0].level == "warning" and "taken from config.yaml" in warnings[0].message
    runs = res.runs.set_index("seed")
    assert set(runs["resolved_from"]) == {runformat.CONFIG}
    assert runs.loc[0, "K"] == 2 and runs.loc[0, "objectives"] == "curl+reward+taco"
    assert pd.isna(runs.loc[0, "latent_action_dim"])  # null in its config: unknown, not recomputed
    assert runs.loc[1, "latent_action_dim"] == 12
    ctx = Context(results=res, out_dir=tmp_path / "out", budget=FRAMES, reps=10)
    assert select.action_dim_runs(ctx.scores)["seed"].tolist() == [1]  # the unknown dim is placed nowhere


def test_malformed_resolved_values_are_a_warning_and_fall_back(tmp_path):
    run = write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=1.0)
    data = json.loads((run / runformat.RESOLVED).read_text())
    data["action_encoder"] = False  # with a latent dim: contradictory
    (run / runformat.RESOLVED).write_text(json.dumps(data))
    res = load_results(tmp_path)
    (problem,) = [p for p in res.problems if p.path == str(run / runformat.RESOLVED)]
    assert problem.level == "warning" and "malformed" in problem.message and "latent_action_dim" in problem.message
    assert res.runs.iloc[0]["resolved_from"] == runformat.CONFIG


def test_resolved_values_are_checked_before_writing(tmp_path):
    good = {"learner": "actor_critic", "K": 3, "batch_size": 8, "action_repeat": 2, "nstep": 3,
            "action_encoder": True, "latent_action_dim": 6, "objectives": {"taco": 1.0}, "dataset": None,
            "cql_alpha": None}
    rundir.write_resolved(tmp_path, {**good, "extra": "kept"})
    assert runformat.read_resolved(tmp_path) == {**good, "extra": "kept"}
    bad = [{k: v for k, v in good.items() if k != "nstep"}, {**good, "latent_action_dim": None},
           {**good, "action_encoder": False}, {**good, "K": 0}, {**good, "objectives": {"curl": 0.0}},
           {**good, "batch_size": True}]
    for values in bad:
        with pytest.raises(runformat.ResolvedError):
            rundir.write_resolved(tmp_path / "x", values)
    assert not (tmp_path / "x").exists()


def test_fixture_configs_go_through_the_training_schema(tmp_path):
    with pytest.raises(ConfigAttributeError):  # the key the old fixtures wrote; the schema has agent.cql.alpha
        run_config("cql", "hopper_hop", 0, tmp_path, **{"agent.cql_alpha": 0.5})
    run = write_run(tmp_path, experiment="offline", agent="cql", task="hopper_hop", seed=0, final=1.0,
                    dataset="medium", cql_alpha=0.5)
    cfg = compose(["agent=drqv2", "task=hopper_hop"])
    saved = rundir.saved_identity(run)
    assert saved is not None and set(saved) == set(cfg) - {"runtime"}
    assert saved["offline"]["dataset"] == "medium" and saved["agent"]["cql"]["alpha"] == 0.5
    row = load_results(tmp_path).runs.iloc[0]
    assert (row["dataset"], row["cql_alpha"], row["learner"]) == ("medium", 0.5, "cql")
