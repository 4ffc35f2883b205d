"""Offline analysis from run directories in the real offline format: loading, T3 cells and average row, T6
from the alpha each run used, the paired ±TACO probability of improvement (T3b) and the offline claims."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import paper_figures  # noqa: E402
from analysis.claims import NO_DATA, REFUTED, SUPPORTED, evaluate_claims  # noqa: E402
from analysis.context import Context  # noqa: E402
from analysis.load import load_results  # noqa: E402
from analysis.offline_tables import offline_runs, taco_poi  # noqa: E402
from analysis.paper import OFFLINE_TASKS, PaperData  # noqa: E402
from analysis.scores import final_scores  # noqa: E402
from analysis.stats import pairwise_poi, poi_interval, probability_of_improvement  # noqa: E402
from analysis_fixtures import write_run
from repro.config.paper_defaults import cql_alpha as table6_alpha  # noqa: E402

# its module-scoped runs are made once: every test of this module on one pytest-xdist worker
pytestmark = pytest.mark.xdist_group("offline_analysis")

DATASETS = ("medium", "medium-replay", "full-replay")
REF = 200.0  # every fixture run's reference return (score_reference "source"): normalised = final / 2
UPDATES = 1000
REPS = 200
BASE = {"td3bc": "TD3+BC", "cql": "CQL"}


def _final(agent: str, task: str, ds: str, seed: int, taco_gain: float) -> float:
    """A distinct return per cell and seed; +TACO runs add ``taco_gain`` to their base's seed."""
    base = 100.0 + 10 * OFFLINE_TASKS.index(task) + 3 * DATASETS.index(ds) + 7 * seed + (5 if agent == "cql" else 0)
    return base + taco_gain if agent.endswith("_taco") else base


def _grid(root: Path, seeds: int = 3, taco_gain: float = 20.0, done: bool = True) -> Path:
    for task in OFFLINE_TASKS:
        for ds in DATASETS:
            for agent in ("td3bc", "td3bc_taco", "cql", "cql_taco"):
                for s in range(seeds):
                    write_run(root, experiment="offline", agent=agent, task=task, dataset=ds, seed=s,
                              final=_final(agent, task, ds, s, taco_gain), updates=UPDATES, eval_every_updates=500,
                              reference=REF, done=done)
    return root


def _ctx(root: Path, out: Path | None = None, **kw) -> Context:
    return Context(results=load_results(root), out_dir=out or root / "report", reps=REPS, render_envs=False, **kw)


def _render(ctx: Context, aid: str) -> pd.DataFrame:
    paper_figures.resolve([aid])[0].render(ctx)
    return pd.read_csv(ctx.out_dir / f"{aid}.csv", keep_default_na=False, na_values=[""])


@pytest.fixture(scope="module")
def grid(tmp_path_factory) -> Path:
    """3 finished seeds of TD3+BC, CQL and their +TACO on every pair, +TACO 20 above each seed of its base,
    and one more seed of TD3+BC on hopper_hop/medium that did not finish its budget (far above the others)."""
    root = _grid(tmp_path_factory.mktemp("offline"))
    write_run(root, experiment="offline", agent="td3bc", task="hopper_hop", dataset="medium", seed=9, final=900.0,
              updates=UPDATES, eval_every_updates=500, reference=REF, done=False)
    return root


@pytest.fixture(scope="module")
def worse(tmp_path_factory) -> Path:
    """As ``grid`` but every +TACO seed 20 below its base's."""
    return _grid(tmp_path_factory.mktemp("worse"), taco_gain=-20.0)


def _copy(root: Path, to: Path, drop: str | None = None, undone: str | None = None) -> Path:
    """A copy of ``root`` without the run folders matching glob ``drop`` and without DONE in those matching
    ``undone`` (runs that did not finish their budget)."""
    shutil.copytree(root, to)
    for run in to.rglob(drop) if drop else ():
        shutil.rmtree(run)
    for run in to.rglob(undone) if undone else ():
        (run / "DONE").unlink(missing_ok=True)
    return to


# ---------------------------------------------------------------- loading
def test_offline_run_loads_identity_budget_and_recorded_score(tmp_path):
    run = write_run(tmp_path, experiment="offline", agent="cql_taco", task="walker_run", dataset="medium-replay",
                    seed=4, final=150.0, updates=UPDATES, eval_every_updates=400, reference=REF)
    # a learner's extra eval column (DT logs its target return) is tolerated
    ev = pd.read_csv(run / "eval.csv").assign(target_return=1.0)
    ev.to_csv(run / "eval.csv", index=False)
    res = load_results(tmp_path)
    assert not [p for p in res.problems if p.level == "error"], res.problems
    row = res.runs.iloc[0]
    assert (row["method"], row["learner"], row["dataset"]) == ("CQL+TACO", "cql", "medium-replay")
    assert row["cql_alpha"] == table6_alpha("walker_run", "medium-replay")  # the config resolved Table 6's
    assert (row["offline_updates"], row["last_update"], row["status"]) == (UPDATES, UPDATES, "done")
    s = final_scores(res).iloc[0]
    assert (s["update"], s["score"], s["normalized"], s["score_reference"]) == (UPDATES, 150.0, 75.0, "source")
    assert bool(s["reached"]) and math.isnan(s["frame"])


def test_offline_eval_with_reordered_updates_is_reported(tmp_path):
    run = write_run(tmp_path, experiment="offline", agent="bc", task="hopper_hop", dataset="medium", seed=0,
                    final=10.0, updates=UPDATES, eval_every_updates=500)
    lines = (run / "eval.csv").read_text().splitlines(keepends=True)
    (run / "eval.csv").write_text("".join([lines[0], lines[2], lines[1], *lines[3:]]))
    res = load_results(tmp_path)
    assert any("update is not strictly increasing" in p.message for p in res.problems)
    assert res.eval.empty


# ---------------------------------------------------------------- T3
def test_t3_cells_and_average_row_from_the_runs(grid, tmp_path):
    t3 = _render(_ctx(grid, tmp_path), "T3").set_index(["task", "dataset", "method"])
    for task in OFFLINE_TASKS:
        for ds in DATASETS:
            for agent, method in (("td3bc", "TD3+BC"), ("cql_taco", "CQL+TACO")):
                values = [_final(agent, task, ds, s, 20.0) / REF * 100 for s in range(3)]
                cell = t3.loc[(task, ds, method)]
                assert cell["n"] == 3
                assert cell["repro_mean"] == pytest.approx(np.mean(values))
                assert cell["repro_std"] == pytest.approx(np.std(values, ddof=1))
                assert cell["ci_low"] <= cell["repro_mean"] <= cell["ci_high"]
    assert t3.loc[("hopper_hop", "medium", "TD3+BC"), "n_short"] == 1  # the unfinished seed 9, left out
    paper = PaperData().offline.set_index(["task", "dataset", "method"])
    cell = t3.loc[("hopper_hop", "medium", "TD3+BC")]
    assert cell["paper_mean"] == paper.loc[("hopper_hop", "medium", "TD3+BC"), "normalized_mean"]
    # 1000 updates: below the 100K from which a run is compared with the paper's (analysis.comparable), so no Δ
    assert pd.isna(cell["paper_in_ci"]) and math.isnan(cell["diff"]) and str(cell["comparable"]) == "False"
    # the average row: the mean over the 12 pairs of the runs' normalised scores, the printed average beside it
    for agent, method, printed in (("td3bc", "TD3+BC", 68.2), ("cql_taco", "CQL+TACO", 72.1)):
        hand = np.mean([_final(agent, t, d, s, 20.0) / REF * 100 for t in OFFLINE_TASKS for d in DATASETS
                        for s in range(3)])
        avg = t3.loc[("Average", "all 12", method)]
        assert avg["repro_mean"] == pytest.approx(hand) and avg["n"] == 3 and avg["paper_mean"] == printed
        assert pd.isna(avg["paper_in_ci"]) and math.isnan(avg["diff"]) and str(avg["comparable"]) == "False"
    # a method without runs has empty cells and no average
    assert t3.loc[("hopper_hop", "medium", "IQL"), "n"] == 0 and math.isnan(t3.loc[("Average", "all 12", "IQL"),
                                                                                   "repro_mean"])
    md = (tmp_path / "T3.md").read_text()
    assert "Normalised by: source (144 runs)" in md and (tmp_path / "T3.tex").stat().st_size > 1000
    assert "| 1,000 updates, not comparable) | 3 |" not in md and "(1,000 updates, not comparable) | 3 |" in md


def test_t3_compares_runs_that_finished_the_papers_updates(tmp_path):
    for s in range(3):
        write_run(tmp_path, experiment="offline", agent="td3bc", task="hopper_hop", dataset="medium", seed=s,
                  final=130.0 + s, updates=100_000, eval_every_updates=50_000, reference=REF)
    cell = _render(_ctx(tmp_path), "T3").set_index(["task", "dataset", "method"]).loc[("hopper_hop", "medium",
                                                                                        "TD3+BC")]
    paper = PaperData().offline.set_index(["task", "dataset", "method"]).loc[("hopper_hop", "medium", "TD3+BC")]
    assert cell["n"] == 3 and str(cell["comparable"]) == "True"
    assert cell["diff"] == pytest.approx(cell["repro_mean"] - paper["normalized_mean"])
    assert bool(cell["paper_in_ci"]) == (cell["ci_low"] <= cell["paper_mean"] <= cell["ci_high"])


def test_t3_average_needs_every_pair(grid, tmp_path):
    root = _copy(grid, tmp_path / "runs", undone="td3bc/base/walker_run/full-replay/seed_*")
    ctx = _ctx(root, tmp_path / "out")
    t3 = _render(ctx, "T3").set_index(["task", "dataset", "method"])
    assert t3.loc[("walker_run", "full-replay", "TD3+BC"), "n"] == 0
    assert t3.loc[("walker_run", "full-replay", "TD3+BC"), "n_short"] == 3
    assert math.isnan(t3.loc[("Average", "all 12", "TD3+BC"), "repro_mean"])
    assert "only 11/12 pairs" in t3.loc[("Average", "all 12", "TD3+BC"), "note"]
    assert not math.isnan(t3.loc[("Average", "all 12", "CQL"), "repro_mean"])
    poi = taco_poi(offline_runs(ctx.scores), ctx.paper, REPS, 0).set_index(["task", "dataset", "method"])
    assert poi.loc[("walker_run", "full-replay", "TD3+BC+TACO"), "n_baseline"] == 0
    assert math.isnan(poi.loc[("All", "all 12", "TD3+BC+TACO"), "poi"])  # a pair without finished runs
    assert poi.loc[("All", "all 12", "CQL+TACO"), "poi"] > 0.5


# ---------------------------------------------------------------- T6
def test_t6_shows_the_alpha_each_run_used(tmp_path):
    table6 = table6_alpha("hopper_hop", "medium")
    assert table6 != 3.0
    write_run(tmp_path, experiment="offline", agent="cql", task="hopper_hop", dataset="medium", seed=0, final=1.0,
              cql_alpha=3.0, updates=UPDATES)
    write_run(tmp_path, experiment="offline", agent="cql_taco", task="cheetah_run", dataset="full-replay", seed=0,
              final=1.0, updates=UPDATES)  # alpha left to the config: Table 6's
    t6 = _render(_ctx(tmp_path), "T6").set_index(["task", "dataset"])
    assert float(t6.loc[("hopper_hop", "medium"), "runs_alpha"]) == 3.0
    assert not bool(t6.loc[("hopper_hop", "medium"), "match"])
    assert float(t6.loc[("cheetah_run", "full-replay"), "runs_alpha"]) == table6_alpha("cheetah_run", "full-replay")
    assert bool(t6.loc[("cheetah_run", "full-replay"), "match"])
    assert pd.isna(t6.loc[("walker_run", "medium"), "match"])


# ---------------------------------------------------------------- ±TACO probability of improvement
def test_pairwise_poi_is_rliables_probability_of_improvement():
    from rliable import metrics

    rng = np.random.default_rng(3)
    for m, n, tasks in ((3, 3, 1), (2, 5, 12), (4, 2, 3)):
        x = rng.integers(0, 4, (m, tasks)).astype(float)  # small integers: ties count a half
        y = rng.integers(0, 4, (n, tasks)).astype(float)
        assert pairwise_poi(x, y) == pytest.approx(metrics.probability_of_improvement(x, y))
    x, y = rng.random((3, 2)), rng.random((3, 2))
    assert poi_interval(x, y, reps=30, seed=1) == pytest.approx(probability_of_improvement(x, y, reps=30, seed=1))


@pytest.mark.parametrize("fixture", ["grid", "worse"])
def test_poi_above_half_when_taco_better_in_every_seed_below_when_worse(request, tmp_path, fixture):
    ctx = _ctx(request.getfixturevalue(fixture), tmp_path)
    raw = _render(ctx, "T3b")
    assert len(raw) == 26 and (tmp_path / "T3b.md").read_text().count("TD3+BC+TACO vs TD3+BC") == 13
    for row in raw.itertuples(index=False):
        assert (row.n_method, row.n_baseline) == (3, 3)  # seed 9 of the grid did not finish: not used
        assert (row.poi > 0.5) if fixture == "grid" else (row.poi < 0.5), row
        assert row.ci_low <= row.poi <= row.ci_high
    again = taco_poi(offline_runs(ctx.scores), ctx.paper, REPS, 0)
    assert np.array_equal(again["ci_low"], raw["ci_low"])  # a fixed random state


# ---------------------------------------------------------------- claims
def _claims(ctx: Context) -> dict:
    return {v.id: v for v in evaluate_claims(ctx)}


def test_offline_claims_judged_from_the_runs(grid, tmp_path):
    v = _claims(_ctx(grid, tmp_path))
    assert v["offline_gain"].verdict == SUPPORTED, v["offline_gain"].evidence
    assert v["offline_average"].verdict in (SUPPORTED, REFUTED)
    assert "TD3+BC+TACO" in v["offline_average"].evidence


def test_offline_claims_refuted_when_taco_lower(worse, tmp_path):
    v = _claims(_ctx(worse, tmp_path))["offline_gain"]
    assert v.verdict == REFUTED and "fails on" in v.evidence


def test_offline_claims_not_enough_data_below_seed_minimum(grid, tmp_path):
    root = _copy(grid, tmp_path / "runs", drop="seed_2")
    v = _claims(_ctx(root, tmp_path / "out"))
    for cid in ("offline_gain", "offline_average"):
        assert v[cid].verdict == NO_DATA and "need >= 3 seeds" in v[cid].evidence, v[cid].evidence


def test_offline_claims_not_enough_data_when_no_run_finished(grid, tmp_path):
    root = _copy(grid, tmp_path / "runs", undone="seed_*")
    v = _claims(_ctx(root, tmp_path / "out"))["offline_gain"]
    assert v.verdict == NO_DATA and "has finished its configured offline.updates" in v.evidence


# ---------------------------------------------------------------- a real offline run
@pytest.mark.slow
def test_real_tiny_cql_run_loads_with_its_resolved_values(tmp_path):
    from offline_fixtures import write_dataset
    from repro.train import api

    root = tmp_path / "runs"
    write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6, best_return=200.0)
    run = api.train(["agent=cql", "task=cheetah_run", "profile=tiny", "seed=0", "runtime.threads=1",
                     "experiment=offline", "offline.dataset=medium", "agent.cql.alpha=3.0", "offline.updates=4",
                     "offline.eval_every_updates=2", "offline.eval_episodes=1", "offline.checkpoint_every_updates=2",
                     "offline.log_every_updates=2", f"runtime.results_root={root}"], echo=lambda s: None)
    res = load_results(root)
    assert not [p for p in res.problems if p.level == "error"], res.problems
    s = final_scores(res)
    assert len(s) == 1
    row = s.iloc[0]
    ev = pd.read_csv(run / "eval.csv")
    assert (row["method"], row["learner"], row["dataset"], row["cql_alpha"]) == ("CQL", "cql", "medium", 3.0)
    assert (row["offline_updates"], row["update"], bool(row["reached"])) == (4, 4, True)
    assert row["normalized"] == pytest.approx(ev["normalized_score"].iloc[-1])
    assert row["score_reference"] == "source" and res.runs.iloc[0]["updates_per_s"] > 0
