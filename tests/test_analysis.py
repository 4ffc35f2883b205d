"""Analysis: loading and validation, scores, statistics (against rliable), claims, audit, CLI errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import typer
import yaml
from rliable import library as rly
from rliable import metrics
from typer.testing import CliRunner

from analysis import select
from analysis.audit import mismatches, run_audit
from analysis.claims import NO_DATA, REFUTED, SUPPORTED, evaluate_claims
from analysis.context import Context
from analysis.load import load_results
from analysis.scores import final_scores, learning_curves
from analysis.speed import hardware_label, speed_measurements
from analysis.stats import (
    aggregate_estimates,
    mean_cis,
    mean_std,
    probability_of_improvement,
    seeded,
)
from analysis_fixtures import DMC9, FRAMES, write_run
from repro.runs.console import Commands
from repro_app.analysis_cli import register

REPS = 200
pytestmark = pytest.mark.filterwarnings("ignore:random_state is deprecated:FutureWarning")


PAPER = 1_000_000  # the paper's budget of Table 1 (environment frames)


def _ctx(root: Path, **kw) -> Context:
    return Context(results=load_results(root), out_dir=root / "_out", **{"budget": FRAMES, "reps": REPS, **kw})


# ---------------------------------------------------------------- loading
def test_identity_comes_from_config_not_path(tmp_path):
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=3, final=100.0, K=1,
              path=tmp_path / "somewhere" / "else")
    res = load_results(tmp_path)
    row = res.runs.iloc[0]
    assert (row["experiment"], row["agent"], row["method"], row["task"], row["seed"], row["K"]) == (
        "main", "taco", "TACO", "hopper_hop", 3, 1)
    assert row["objectives"] == "curl+reward+taco"
    assert row["run_id"] == "somewhere/else"
    assert set(res.eval["run_id"]) == {"somewhere/else"}


def test_malformed_files_are_reported_with_path_and_skipped(tmp_path):
    good = write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=100.0)
    extra_field = write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=1, final=100.0)
    with open(extra_field / "eval.csv", "a") as fh:
        fh.write("120000,60000,7,1.0,0.0,500,,10,7,EXTRA\n")
    truncated = write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=2, final=100.0)
    text = (truncated / "eval.csv").read_text()
    (truncated / "eval.csv").write_text(text[:-9])  # cut inside the last row
    bad_train = write_run(tmp_path, experiment="main", agent="drqv2", task="hopper_hop", seed=0, final=50.0)
    (bad_train / "train.csv").write_text("frame,step\n1,2\n")
    no_config = tmp_path / "orphan"
    no_config.mkdir()
    (no_config / "eval.csv").write_text((good / "eval.csv").read_text())
    bad_yaml = write_run(tmp_path, experiment="main", agent="taco", task="walker_run", seed=0, final=1.0)
    (bad_yaml / "config.yaml").write_text("experiment: [unclosed\n")
    nameless = write_run(tmp_path, experiment="main", agent="taco", task="walker_run", seed=1, final=1.0)
    cfg = yaml.safe_load((nameless / "config.yaml").read_text())
    del cfg["agent"]["name"]
    (nameless / "config.yaml").write_text(yaml.safe_dump(cfg))

    res = load_results(tmp_path)
    paths = {p.path: p.message for p in res.problems}
    assert str(extra_field / "eval.csv") in paths and "fields" in paths[str(extra_field / "eval.csv")]
    assert str(truncated / "eval.csv") in paths and "truncated" in paths[str(truncated / "eval.csv")]
    assert str(bad_train / "train.csv") in paths
    assert str(no_config / "eval.csv") in paths
    assert str(bad_yaml / "config.yaml") in paths
    assert paths[str(nameless / "config.yaml")] == "config lacks agent.name; run skipped"  # the config's key
    # the good run keeps its rows; the malformed eval files contribute none
    assert set(res.eval["run_id"]) == {str(good.relative_to(tmp_path)), str(bad_train.relative_to(tmp_path))}
    assert math.isnan(res.runs.set_index("run_id").loc[str(bad_train.relative_to(tmp_path)), "fps"])


def test_missing_root_raises_clear_error(tmp_path):
    from analysis.load import ResultsRootError

    with pytest.raises(ResultsRootError, match="does not exist"):
        load_results(tmp_path / "nope")


# ---------------------------------------------------------------- scores
def test_score_at_budget_takes_largest_frame_not_past_budget(tmp_path):
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=500.0)
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=1, final=500.0, frames=60_000,
              done=False)
    res = load_results(tmp_path)
    s = final_scores(res, 100_000).set_index("seed")
    assert s.loc[0, "score"] == pytest.approx(500.0) and bool(s.loc[0, "reached"])
    assert s.loc[1, "score"] == pytest.approx(500.0) and s.loc[1, "frame"] == 60_000  # its last evaluation
    assert not bool(s.loc[1, "reached"])  # flagged short
    s70 = final_scores(res, 70_000).set_index("seed")
    assert s70.loc[0, "frame"] == 60_000 and s70.loc[0, "score"] == pytest.approx(300.0)
    assert bool(s70.loc[0, "reached"])


def test_learning_curves_interpolate_and_do_not_extrapolate(tmp_path):
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=100.0)
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=1, final=100.0, frames=40_000)
    res = load_results(tmp_path)
    curves = learning_curves(res, grid=np.array([0.0, 10_000.0, 50_000.0]))
    by_seed = {s: dict(zip(g["frame"], g["value"])) for s, g in curves.groupby("seed")}
    assert by_seed[0] == {0.0: 0.0, 10_000.0: pytest.approx(10.0), 50_000.0: pytest.approx(50.0)}
    assert 50_000.0 not in by_seed[1]  # past its last evaluation


def _curves_run_by_run(results, grid):
    """learning_curves as it was written first: one frame per run, concatenated (the reference of the whole-table
    version)."""
    from analysis.load import IDENTITY
    from analysis.scores import _values, metric_of, on_grid

    online = on_grid(results.eval[results.eval["frame"].notna()])
    parts = []
    for _, rows in online.groupby("run_id", sort=False):
        rows = rows.sort_values("frame")
        vals = _values(rows, metric_of(rows["suite"].iloc[0])).to_numpy(dtype=float)
        frames = rows["frame"].to_numpy(dtype=float)
        ok = ~np.isnan(vals)
        if not ok.any():
            continue
        g = grid[(grid >= frames[ok][0]) & (grid <= frames[ok][-1])]
        parts.append(pd.DataFrame({"frame": g, "value": np.interp(g, frames[ok], vals[ok]),
                                   **{key: rows[key].iloc[0] for key in IDENTITY}}))
    return pd.concat(parts, ignore_index=True)[[*IDENTITY, "frame", "value"]]


def test_learning_curves_equal_the_run_by_run_curves(tmp_path):
    """Every run at once gives each run's curve and each identity column's type as one frame per run did: DMC and
    Meta-world runs, a run with no score, an offline run (no curve), identity columns of Python objects."""
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=100.0)
    write_run(tmp_path, experiment="main", agent="drqv2", task="hopper_hop", seed=1, final=70.0, frames=40_000)
    write_run(tmp_path, experiment="metaworld", agent="taco", task="hammer", seed=0, final=0.8, success=True)
    write_run(tmp_path, experiment="offline", agent="cql_taco", task="hopper_hop", seed=0, final=100.0,
              dataset="medium_replay", reference=250.0)
    res = load_results(tmp_path)
    grid = np.arange(0.0, 110_000.0, 7_000.0)
    pd.testing.assert_frame_equal(learning_curves(res, grid=grid), _curves_run_by_run(res, grid), check_exact=True)
    nan_run = res.eval["seed"] == 1
    res.eval.loc[nan_run, "episode_reward"] = np.nan  # a run without a score has no curve
    res.eval["K"] = res.eval["K"].astype(object)  # Python integers: int64 as one frame per run made it
    res.eval["variant"] = np.where(res.eval["suite"] == "dmc", None, res.eval["variant"])
    res.eval["action_encoder"] = res.eval["action_encoder"].astype(object)
    res.eval.loc[res.eval["suite"] == "metaworld", "action_encoder"] = None
    new, old = learning_curves(res, grid=grid), _curves_run_by_run(res, grid)
    assert new["K"].dtype == np.int64 and new["action_encoder"].dtype == object
    pd.testing.assert_frame_equal(new, old, check_exact=True)


def test_metaworld_score_is_success_percent(tmp_path):
    write_run(tmp_path, experiment="metaworld", agent="taco", task="hammer", seed=0, final=0.8, success=True)
    s = final_scores(load_results(tmp_path), FRAMES)
    assert s.iloc[0]["metric"] == "success" and s.iloc[0]["score"] == pytest.approx(80.0)


def test_offline_score_is_the_normalised_score_the_run_recorded(tmp_path):
    write_run(tmp_path, experiment="main", agent="taco", task="hopper_hop", seed=0, final=400.0)
    write_run(tmp_path, experiment="offline", agent="cql_taco", task="hopper_hop", seed=0, final=100.0,
              dataset="medium_replay", reference=250.0)
    off = final_scores(load_results(tmp_path), FRAMES).dropna(subset=["dataset"])
    row = off.iloc[0]
    assert (row["method"], row["dataset"]) == ("CQL+TACO", "medium-replay")
    assert row["normalized"] == pytest.approx(40.0) and row["score_reference"] == "source"  # not the online run's


# ---------------------------------------------------------------- statistics vs rliable
def test_mean_std_uses_ddof_1():
    n, mean, std = mean_std([530.0, 540.0, 550.0])
    assert (n, mean, std) == (3, 540.0, 10.0)
    assert math.isnan(mean_std([1.0])[2])


def test_cell_cis_equal_rliables_own():
    rng = np.random.default_rng(1)
    cols = [rng.uniform(0, 1000, 5) for _ in range(3)]
    ours = mean_cis(cols, reps=REPS, seed=7)
    np.random.seed(7)
    _, cis = rly.get_interval_estimates({"cells": np.stack(cols, axis=1)}, lambda x: np.mean(x, axis=0), reps=REPS,
                                        random_state=np.random.RandomState(7))
    assert ours == [(float(cis["cells"][0][j]), float(cis["cells"][1][j])) for j in range(3)]
    single = mean_cis([np.array([3.0])], reps=REPS)
    assert math.isnan(single[0][0]) and math.isnan(single[0][1])


def test_aggregates_and_poi_equal_rliables_own():
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 1, (4, 3)), rng.uniform(0, 1, (5, 3))
    df = aggregate_estimates({"A": x}, reps=REPS, seed=3).set_index("metric")

    def agg(s):
        return np.array([metrics.aggregate_iqm(s), metrics.aggregate_mean(s), metrics.aggregate_optimality_gap(s)])

    np.random.seed(3)
    points, cis = rly.get_interval_estimates({"A": x}, agg, reps=REPS, random_state=np.random.RandomState(3))
    for k, name in enumerate(["IQM", "Mean", "Optimality Gap"]):
        assert df.loc[name, "value"] == pytest.approx(points["A"][k], abs=0)
        assert (df.loc[name, "ci_low"], df.loc[name, "ci_high"]) == (cis["A"][0][k], cis["A"][1][k])
    p, lo, hi = probability_of_improvement(x, y, reps=REPS, seed=4)
    np.random.seed(4)
    pt, ci = rly.get_interval_estimates({"p": [x, y]},
                                        lambda a, b: np.array([metrics.probability_of_improvement(a, b)]),
                                        reps=REPS, random_state=np.random.RandomState(4))
    assert (p, lo, hi) == (pt["p"][0], ci["p"][0][0], ci["p"][1][0])


def test_seeded_restores_global_numpy_state():
    np.random.seed(123)
    expected = np.random.rand()
    np.random.seed(123)
    with seeded(0):
        np.random.rand(10)
    assert np.random.rand() == expected


# ---------------------------------------------------------------- artifacts: exact cells
def test_t1_cells_exact(tmp_path):
    # at the paper's budget (1M frames): a run that reached it is compared with the paper (Δ, Paper in CI)
    for s, v in enumerate((530.0, 540.0, 550.0)):
        write_run(tmp_path, experiment="main", agent="taco", task="quadruped_run", seed=s, final=v, frames=PAPER,
                  eval_every=PAPER // 4)
    write_run(tmp_path, experiment="main", agent="drqv2", task="quadruped_run", seed=0, final=400.0, frames=60_000,
              done=False)
    from paper_figures.t1_online import render

    ctx = _ctx(tmp_path, budget=PAPER)
    table = render(ctx).tables[0]
    t = table.data.set_index(["task", "method"])
    taco = t.loc[("quadruped_run", "TACO")]
    got = (taco["n"], taco["repro_mean"], taco["repro_std"], taco["paper_mean"], taco["diff"])
    assert got == (3, 540.0, 10.0, 541.0, -1.0)
    lo, hi = mean_cis([np.array([530.0, 540.0, 550.0])], reps=REPS, seed=0)[0]
    assert (taco["ci_low"], taco["ci_high"]) == (lo, hi)
    assert taco["paper_in_ci"] == (lo <= 541.0 <= hi)
    drq = t.loc[("quadruped_run", "DrQ-v2")]
    assert (drq["n"], drq["n_short"]) == (0, 1) and math.isnan(drq["repro_mean"])  # short run counted, not used
    assert t.loc[("hopper_hop", "DreamerV3"), "n"] == 0  # empty cells are kept
    md = (ctx.out_dir / "T1.md").read_text()
    assert ("| Task | Method | Paper (1M env. frames, action repeat 2) | Reproduced (1M env. frames, action repeat 2) "
            "| n | 95% CI | Δ | Paper in CI |") in md
    assert "| Quadruped Run | TACO | 541 ± 38 | 540 ± 10 | 3 |" in md
    assert "| Quadruped Run | DrQ-v2 | 407 ± 21 | no runs | 0 (+1 short, at 60K frames) |" in md
    assert bool(taco["comparable"]) and "not comparable" not in md
    assert (ctx.out_dir / "T1.tex").read_text().count(r"\\") > 60 and (ctx.out_dir / "T1.csv").exists()


def test_experiment_map_reads_other_experiment_names(tmp_path):
    write_run(tmp_path, experiment="tiny", agent="taco", task="hopper_hop", seed=0, final=10.0)
    ctx = _ctx(tmp_path)
    assert select.online_main(ctx.scores).empty
    mapped = select.online_main(ctx.scores, {"main": ["tiny"]})
    assert list(mapped["label"]) == ["TACO"]


# ---------------------------------------------------------------- a value beside the paper's only where comparable
def test_the_comparability_rule():
    from analysis.comparable import UPDATES, Budget, comparable, paper_frames, paper_updates

    paper = paper_frames()
    assert (paper.value, paper.repeats, paper.text()) == (1_000_000, (2,), "1M env. frames (action repeat 2)")
    assert comparable(Budget(1_000_000, repeats=(2,)), paper) and comparable(Budget(1_000_000, repeats=(4,)), paper)
    assert not comparable(Budget(400), paper) and not comparable(Budget(2_000_000), paper)  # another budget
    assert not comparable(None, paper)  # no run reached it
    assert not comparable(Budget(1_000_000, UPDATES), paper)  # another unit
    offline = paper_updates()  # the paper states none: from the default offline.updates (100K) on
    assert offline.at_least and offline.value == 100_000
    assert not comparable(Budget(20, UPDATES), offline) and comparable(Budget(550_000, UPDATES), offline)
    assert comparable(None, None) and comparable(Budget(400), None)  # a paper value without a budget (a timing)


def test_a_run_reaches_a_budget_only_by_an_evaluation_there(tmp_path):
    """One rule of 'reached' (analysis.comparable.reached): a run done with train.frames at the budget whose last
    evaluation is before it did not reach it, for the scores (and so every table and claim), the claims' budget and
    `repro verify`, which reads the same rule; verify's table states the frames reached with their repeat."""
    from analysis import verify
    from analysis.comparable import reached

    assert reached(1_000_000, 1_000_000) and not reached(999_999, 1_000_000)
    assert not reached(math.nan, 0) and not reached(None, 0)

    def cut(run: Path, last: int) -> None:  # the evaluations after ``last`` lost; the run stays done
        lines = (run / "eval.csv").read_text().splitlines()
        frame = lines[0].split(",").index("frame")
        (run / "eval.csv").write_text("\n".join([lines[0], *(ln for ln in lines[1:]
                                                            if int(ln.split(",")[frame]) <= last)]) + "\n")

    for s in range(3):
        cut(write_run(tmp_path, experiment="main", agent="taco", task="quadruped_run", seed=s, final=400.0 + s,
                      frames=PAPER, eval_every=PAPER // 2), PAPER // 2)
        cut(write_run(tmp_path, experiment="verify", agent="drqv2", task="cartpole_balance", seed=s + 1, final=0.0,
                      frames=60_000, eval_every=20_000, curve=[350, 300, 800, 980], batch_size=256), 40_000)
    ctx = _ctx(tmp_path, budget=PAPER)
    main = ctx.scores[ctx.scores["experiment"] == "main"]
    assert (main["status"] == "done").all() and (main["train_frames"] == PAPER).all()
    assert not main["reached"].any() and (main["last_frame"] == PAPER // 2).all()
    claim = {v.id: v for v in evaluate_claims(ctx)}["online_beats_drqv2_all"]
    assert claim.verdict == NO_DATA and "runs reach 500,000 frames" in claim.evidence
    assert claim.budget == "1M env. frames (action repeat 2)"  # the unit and the repeat beside the frames
    row = verify.judge(load_results(tmp_path), random_returns={"cartpole_balance": 300.0})[0]
    assert row.verdict == verify.NOT_ENOUGH and row.reached == 40_000 and "they reach 40,000 frames" in row.note
    assert verify.verdict_display([row])["Env. frames reached"].tolist() == ["40,000 frames (action repeat 2)"]


def test_a_short_run_is_shown_as_not_comparable_without_delta_or_in_ci(tmp_path):
    # `make repro`'s situation: 400-frame runs of 100-frame episodes under experiment tiny, read as main at 400
    for s in (1, 2):
        for agent, final in (("taco", 1.0), ("drqv2", 2.0)):
            write_run(tmp_path, experiment="tiny", agent=agent, task="cheetah_run", seed=s, final=final + s,
                      frames=400, eval_every=200, config={"env.max_episode_frames": 100})
    from paper_figures.t1_online import render

    ctx = _ctx(tmp_path, budget=400, experiment_map={"main": ["tiny"]})
    table = render(ctx).tables[0]
    taco = table.data.set_index(["task", "method"]).loc[("cheetah_run", "TACO")]
    assert taco["n"] == 2 and taco["repro_mean"] == 2.5  # the value is shown, as what it is
    assert math.isnan(taco["diff"]) and taco["paper_in_ci"] is None and not taco["comparable"]
    assert (taco["budget"], taco["budget_unit"], taco["paper_budget"]) == (400, "frames", "1M frames")
    md = (ctx.out_dir / "T1.md").read_text()
    row = next(ln for ln in md.splitlines() if ln.startswith("| Cheetah Run | TACO |"))
    assert row.startswith("| Cheetah Run | TACO | 821 ± 48 | 2 ± 1 (400 frames, not comparable) | 2 |")
    assert "| n/a | n/a |" in row and "-820" not in row  # no Δ, no "Paper in CI"
    assert "100-frame episodes (paper: 1,000)" in row  # the run's environment, labelled
    assert "| Paper (1M env. frames, action repeat 2) | Reproduced (400 env. frames, action repeat 2) |" in md
    assert "Not comparable: reproduced values at 400 env. frames (action repeat 2), the paper's at 1M env. " in md
    assert "Frames are environment frames = agent steps x action repeat (the paper: action repeat 2" in md

    # the same runs at the paper's budget: no run reached it, and the short ones say where they stopped
    ctx = _ctx(tmp_path, budget=1_000_000, experiment_map={"main": ["tiny"]})
    render(ctx)
    md = (ctx.out_dir / "T1.md").read_text()
    assert "| Cheetah Run | TACO | 821 ± 48 | no runs | 0 (+2 short, at 400 frames) | — | — | — |" in md


def test_runs_of_another_environment_are_labelled():
    from analysis.comparable import env_difference, env_differences

    base = {"suite": "dmc", "action_repeat": 2, "max_episode_frames": None, "camera": None, "distracting_dims": 0}
    assert env_difference(base) == [] and env_difference({**base, "max_episode_frames": 1000}) == []
    assert env_difference({**base, "max_episode_frames": 100}) == ["100-frame episodes (paper: 1,000)"]
    assert env_difference({**base, "action_repeat": 4}) == ["action repeat 4 (paper: 2)"]
    assert env_difference({**base, "action_repeat": 4}, varied=("action_repeat",)) == []  # F9's own variable
    assert env_difference({**base, "camera": "1"}) == ["camera 1 (paper: the task's own)"]
    assert env_difference({**base, "distracting_dims": 20}) == ["20 distracting action dims (paper: 0)"]
    rows = pd.DataFrame([{**base, "max_episode_frames": 100}, base])
    assert env_differences(rows) == "100-frame episodes (paper: 1,000) (1 of 2 runs)"


def test_an_offline_run_below_the_papers_updates_is_not_compared(tmp_path):
    for agent in ("td3bc", "td3bc_taco"):
        for s in (1, 2):
            write_run(tmp_path, experiment="offline", agent=agent, task="cheetah_run", seed=s, final=10.0 + s,
                      dataset="medium", updates=20, eval_every_updates=10)
    from paper_figures.t3_offline import render

    ctx = _ctx(tmp_path)
    table = render(ctx).tables[0]
    cell = table.data.set_index(["task", "dataset", "method"]).loc[("cheetah_run", "medium", "TD3+BC")]
    assert cell["n"] == 2 and math.isnan(cell["diff"]) and cell["paper_in_ci"] is None and not cell["comparable"]
    md = (ctx.out_dir / "T3.md").read_text()
    assert "(20 updates, not comparable) | 2 |" in md and "| Reproduced (20 gradient updates) |" in md
    assert "the paper's at an unstated number of updates (a run is compared from 100K updates on)" in md


def test_claims_without_runs_name_the_experiments_that_have_them_and_the_x_option(tmp_path):
    from analysis.claim_budget import unread_hints

    for s in (1, 2):
        write_run(tmp_path, experiment="tiny", agent="taco", task="cheetah_run", seed=s, final=1.0, frames=400,
                  eval_every=200)
        write_run(tmp_path, experiment="tiny_offline", agent="td3bc", task="cheetah_run", seed=s, final=1.0,
                  dataset="medium", updates=20, eval_every_updates=10)
    ctx = _ctx(tmp_path)
    v = _verdicts(ctx)
    hint = "runs exist in experiment(s) tiny (2 online runs): `-x main=tiny` reads them as experiment main"
    assert "no runs in experiment(s) main" in v["online_avg_gain"].evidence and hint in v["online_avg_gain"].evidence
    assert ("`-x offline=tiny_offline` reads them as experiment offline" in v["offline_gain"].evidence
            and "tiny_offline (2 offline runs)" in v["offline_gain"].evidence)
    assert unread_hints(ctx.scores, {}) == [
        hint, "runs exist in experiment(s) tiny_offline (2 offline runs): `-x offline=tiny_offline` reads them as "
        "experiment offline"]
    mapped = _ctx(tmp_path, experiment_map={"main": ["tiny"], "offline": ["tiny_offline"]})
    assert unread_hints(mapped.scores, mapped.experiment_map) == []
    assert "runs reach 400 frames" in _verdicts(mapped)["online_avg_gain"].evidence  # the hint's option reads them
    out = CliRunner().invoke(_app(), ["claims", "--results", str(tmp_path), "--out", str(tmp_path / "out"),
                                      "--reps", "50"])
    assert out.exit_code == 0 and "Hint: Runs exist in experiment(s) tiny (2 online runs): `-x main=tiny`" in out.output


def test_speed_from_runs_and_bench(tmp_path):
    write_run(tmp_path, experiment="speed", agent="taco", task="hopper_hop", seed=0, final=1.0, fps=12.0,
              device="cuda:NVIDIA A100")
    (tmp_path / "bench").mkdir()
    (tmp_path / "bench" / "b.json").write_text('{"hardware": "CPU: X", "results": [{"algo": "drqv2", '
                                               '"batch_size": 256, "update_seconds": 0.1, "fps_estimate": 40.0}]}')
    (tmp_path / "bench" / "broken.json").write_text("{")
    res = load_results(tmp_path)
    m = speed_measurements(res).set_index("method")
    assert m.loc["TACO", "fps"] == 12.0 and m.loc["TACO", "hardware"] == "NVIDIA A100 (GPU)"
    assert m.loc["DrQ-v2", "fps"] == 40.0 and m.loc["DrQ-v2", "hardware"] == "CPU: X"
    assert any(p.path.endswith("broken.json") for p in res.problems)
    assert hardware_label("cpu", "Intel Xeon") == "CPU: Intel Xeon"


# ---------------------------------------------------------------- claims
CLAIM_FRAMES = 1_000_000  # the budget of the main-table claims (analysis/claim_budgets.csv)


def _main_grid(root: Path, taco: dict[str, float], seeds: int = 3, frames: int = CLAIM_FRAMES,
               experiment: str = "main") -> None:
    for task in DMC9:
        for s in range(seeds):
            write_run(root, experiment=experiment, agent="drqv2", task=task, seed=s, final=400.0 + s, frames=frames,
                      eval_every=frames // 4)
            if task in taco:
                write_run(root, experiment=experiment, agent="taco", task=task, seed=s, final=taco[task] + s,
                          frames=frames, eval_every=frames // 4)


def _verdicts(ctx: Context) -> dict[str, object]:
    return {v.id: v for v in evaluate_claims(ctx)}


def test_claim_verdicts_supported_refuted_and_not_enough_data(tmp_path):
    good = tmp_path / "good"
    _main_grid(good, {t: 600.0 for t in DMC9})
    v = _verdicts(_ctx(good))
    assert v["online_beats_drqv2_all"].verdict == SUPPORTED
    assert v["online_avg_gain"].verdict == SUPPORTED and "1.49" in v["online_avg_gain"].evidence
    assert v["manipulator"].verdict == NO_DATA and v["tsne_clusters"].verdict == NO_DATA

    bad = tmp_path / "bad"
    _main_grid(bad, {**{t: 600.0 for t in DMC9}, "hopper_hop": 300.0})
    v = _verdicts(_ctx(bad))
    assert v["online_beats_drqv2_all"].verdict == REFUTED and "hopper_hop" in v["online_beats_drqv2_all"].evidence

    partial = tmp_path / "partial"
    _main_grid(partial, {"hopper_hop": 300.0})  # a counterexample refutes a universal claim even with gaps
    v = _verdicts(_ctx(partial))
    assert v["online_beats_drqv2_all"].verdict == REFUTED
    assert v["online_avg_gain"].verdict == NO_DATA

    gaps = tmp_path / "gaps"
    _main_grid(gaps, {"hopper_hop": 700.0})
    assert _verdicts(_ctx(gaps))["online_beats_drqv2_all"].verdict == NO_DATA


def test_claim_min_seeds_come_from_the_budget_table(tmp_path):
    two = tmp_path / "two"
    _main_grid(two, {t: 600.0 for t in DMC9}, seeds=2)
    v = _verdicts(_ctx(two, min_seeds=1))["online_beats_drqv2_all"]  # --min-seeds cannot go below the table's 3
    assert v.verdict == NO_DATA and "need >= 3 seeds that reached 1M frames" in v.evidence and v.min_seeds == 3
    three = tmp_path / "three"
    _main_grid(three, {t: 600.0 for t in DMC9}, seeds=3)
    assert _verdicts(_ctx(three, min_seeds=1))["online_beats_drqv2_all"].verdict == SUPPORTED
    assert _verdicts(_ctx(three, min_seeds=4))["online_beats_drqv2_all"].verdict == NO_DATA  # but can go above


def test_claims_below_their_budget_are_not_enough_data_with_the_reason(tmp_path):
    # tiny runs (400 frames, 2 seeds) in which TACO loses everywhere: a universal claim is NOT refuted
    _main_grid(tmp_path, {t: 300.0 for t in DMC9}, seeds=2, frames=400)
    ctx = _ctx(tmp_path)
    ctx.budget = 400  # even when the tables are scored at the runs' own budget (as `repro reproduce` does)
    verdicts = evaluate_claims(ctx)
    assert {v.verdict for v in verdicts} == {NO_DATA}
    v = {x.id: x for x in verdicts}
    assert "runs reach 400 frames; the claim is about 1M frames" in v["online_beats_drqv2_all"].evidence
    assert "the claim is about 2M frames" in v["longer_training"].evidence
    assert "the claim is about 30M frames" in v["manipulator"].evidence
    assert all(not x.indicative for x in verdicts)


def test_claims_at_their_own_budget_not_the_tables(tmp_path):
    """Runs at 1M frames carry the 1M claims, not the 2M claim; runs at 2M carry both."""
    _main_grid(tmp_path / "m1", {t: 600.0 for t in DMC9})
    v = _verdicts(_ctx(tmp_path / "m1"))
    assert v["online_beats_drqv2_all"].verdict == SUPPORTED
    assert v["longer_training"].verdict == NO_DATA and "the claim is about 2M frames" in v["longer_training"].evidence
    _main_grid(tmp_path / "m2", {t: 600.0 for t in DMC9}, frames=2_000_000)
    v = _verdicts(_ctx(tmp_path / "m2"))
    assert v["longer_training"].verdict == SUPPORTED, v["longer_training"].evidence
    assert v["online_beats_drqv2_all"].verdict == SUPPORTED  # scored at 1M frames within the 2M runs


def test_indicative_reading_is_labelled_and_never_a_verdict(tmp_path):
    _main_grid(tmp_path / "ahead", {t: 600.0 for t in DMC9}, seeds=2, frames=400)
    v = _verdicts(_ctx(tmp_path / "ahead", indicative=True))
    w = v["online_beats_drqv2_all"]
    assert w.verdict == NO_DATA and w.shown == w.indicative
    assert w.indicative == "indicative: TACO ahead on every task (400 frames, 2 seeds)"
    assert "runs reach 400 frames; the claim is about 1M frames" in w.evidence and "indicative reading" in w.evidence
    _main_grid(tmp_path / "behind", {t: 300.0 for t in DMC9}, seeds=2, frames=400)
    w = _verdicts(_ctx(tmp_path / "behind", indicative=True))["online_beats_drqv2_all"]
    assert w.verdict == NO_DATA and w.indicative == "indicative: TACO behind on some task (400 frames, 2 seeds)"
    # without the flag there is no reading at all
    assert _verdicts(_ctx(tmp_path / "ahead"))["online_beats_drqv2_all"].indicative == ""


def test_offline_claims_use_each_runs_own_budget(tmp_path):
    from analysis.paper import OFFLINE_TASKS

    def grid(root: Path, done: bool) -> None:
        for task in OFFLINE_TASKS:
            for ds in ("medium", "medium_replay", "full_replay"):
                for agent in ("td3bc", "cql"):
                    for s in range(3):
                        for taco, final in ((False, 300.0), (True, 330.0)):
                            write_run(root, experiment="offline", agent=f"{agent}_taco" if taco else agent, task=task,
                                      dataset=ds, seed=s, final=final + s, updates=1000, eval_every_updates=500,
                                      done=done)

    grid(tmp_path / "unfinished", done=False)
    v = _verdicts(_ctx(tmp_path / "unfinished"))["offline_gain"]
    assert v.verdict == NO_DATA and "has finished its configured offline.updates" in v.evidence
    grid(tmp_path / "finished", done=True)  # 1000 updates is no obstacle: the budget is the run's own
    v = _verdicts(_ctx(tmp_path / "finished"))["offline_gain"]
    assert v.verdict == SUPPORTED, v.evidence


def test_every_claim_has_a_budget_matching_its_text():
    from analysis.claim_budget import load_budgets
    from analysis.paper import PaperData

    budgets = load_budgets()
    claims = PaperData().claims.set_index("id")["claim"]
    assert set(budgets) == set(claims.index)
    for cid, text in claims.items():
        for words, frames in (("at 1M", 1_000_000), (", 1M", 1_000_000), ("30M frames", 30_000_000)):
            if words in text:
                assert budgets[cid].budget == frames, cid
    assert budgets["longer_training"].budget == 2_000_000 and budgets["offline_gain"].kind == "offline_updates"
    assert all(b.min_seeds <= b.paper_seeds or b.paper_seeds == 1 for b in budgets.values())


def test_report_of_tiny_runs_shows_no_verdict(tmp_path):
    from repro_app.report import build_markdown

    # 3 seeds (the claims' minimum) so that only the budget stands between these runs and a verdict
    _main_grid(tmp_path, {t: 300.0 for t in DMC9}, seeds=3, frames=400)
    ctx = _ctx(tmp_path, min_seeds=1)
    ctx.budget = 400
    md = build_markdown(ctx, [], evaluate_claims(ctx), [])
    assert "**Claims:** 21 rows (the paper's 20 claims and online_avg_gain read against the published DrQ-v2 " \
        "curves): 0 supported, 0 refuted, 21 not enough data" in md
    section = md.split("## Claims", 1)[1].split("\n## ", 1)[0]
    rows = [ln for ln in section.splitlines() if ln.startswith("| ") and ln.split("|")[1].strip() in _verdicts(ctx)]
    # 20 claims + the reading of online_avg_gain against the published DrQ-v2 curves (analysis/calibration.py)
    assert len(rows) == 21 and all(ln.split("|")[2].strip() == NO_DATA for ln in rows)
    ctx = _ctx(tmp_path, indicative=True)
    md = build_markdown(ctx, [], evaluate_claims(ctx), [])
    assert "| indicative: TACO behind on some task (400 frames, 3 seeds) |" in md
    assert "): 0 supported, 0 refuted" in md


def test_action_repeat_claim_refuted_when_best_k_differs(tmp_path):
    for ar in (1, 2, 4):
        for k in (1, 3, 5):
            for s in range(3):
                write_run(tmp_path, experiment="action_repeat", agent="taco", task="hopper_hop", K=k, action_repeat=ar,
                          variant=f"ar{ar}_K{k}", seed=s, final=100.0 * k + s, frames=CLAIM_FRAMES,
                          eval_every=CLAIM_FRAMES // 2)  # K=5 always best
    v = _verdicts(_ctx(tmp_path))["action_repeat"]
    assert v.verdict == REFUTED and "AR4: K=5" in v.evidence


# ---------------------------------------------------------------- audit of the paper's numbers
def test_audit_finds_the_papers_real_mismatches():
    findings = run_audit()
    bad = {(f.check, f.description.split(":")[0]) for f in mismatches(findings)}
    by_desc = {f.description: f for f in findings}
    # Table 3's printed average row swaps DT and BC: DT's 12 cells average 54.9, BC's 48.4
    dt = next(f for f in findings if f.check == "offline_average_row" and ", DT:" in f.description)
    assert not dt.match and dt.printed == "48.4" and "54.9" in dt.recomputed and "BC" in dt.description
    bc = next(f for f in findings if f.check == "offline_average_row" and ", BC:" in f.description)
    assert not bc.match and bc.printed == "54.9" and "48.4" in bc.recomputed
    assert all(f.match for f in findings if f.check == "offline_average_row" and "DT" not in f.description
               and ", BC:" not in f.description)
    # Table 2 repeats Table 1's TACO/DrQ-v2 entries, three of them differently
    t12 = {f.description.split(":")[0]: f for f in findings if f.check == "t1_vs_t2" and not f.match}
    assert set(t12) == {"walker_run TACO", "hopper_hop DrQ-v2", "acrobot_swingup DrQ-v2"}
    assert t12["walker_run TACO"].printed == "T2: 637 ± 21" and t12["walker_run TACO"].recomputed == "T1: 637 ± 11"
    assert "DreamerV3" in t12["acrobot_swingup DrQ-v2"].description
    # 130 / 35 = 3.71, printed as "3.6 times": 3.648-3.783 with each FPS within its printed ±0.5, so rounding
    speed = next(f for f in findings if f.check == "speed_ratio")
    assert speed.match and speed.recomputed.startswith("3.714") and "rounding, not a mismatch" in speed.recomputed
    # checks that agree
    assert next(f for f in findings if f.check == "online_gain_ratio").match  # 1.397 -> 1.4x
    assert next(f for f in findings if f.check == "t4_vs_t5").match
    assert next(f for f in findings if f.check == "beats_model_based").match
    assert all(f.match for f in findings if f.check == "csv_vs_tex")
    assert ("action_repr_reacher", "reacher_hard") in bad
    assert len(by_desc) == len(findings)


# ---------------------------------------------------------------- CLI
def _app() -> typer.Typer:
    app = typer.Typer(cls=Commands)  # as `repro` catches a UserError: one line, exit 2
    register(app)
    return app


@pytest.mark.parametrize(
    "args, needle",
    [
        (["figures", "F99"], "unknown artifact 'F99'"),
        (["figures", "T1", "--results", "/nonexistent/root"], "does not exist"),
        (["claims", "--results", "/nonexistent/root"], "does not exist"),
        (["figures"], "--all or --list"),
        (["report", "--results", "/nonexistent/root"], "does not exist"),
    ],
)
def test_cli_bad_input_is_one_line_and_nonzero(args, needle):
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.output


def test_cli_list_and_audit(tmp_path):
    runner = CliRunner()
    listed = runner.invoke(_app(), ["figures", "--list"])
    assert listed.exit_code == 0 and "F7a" in listed.output and "T6" in listed.output
    audit = runner.invoke(_app(), ["audit", "--out", str(tmp_path)])
    assert audit.exit_code == 0 and "MISMATCH" in audit.output and (tmp_path / "audit.md").exists()
    assert pd.read_csv(tmp_path / "audit.csv")["match"].eq(False).sum() >= 7


def test_cli_claims_indicative_flag(tmp_path):
    _main_grid(tmp_path / "runs", {t: 600.0 for t in DMC9}, seeds=2, frames=400)
    args = ["claims", "--results", str(tmp_path / "runs"), "--out", str(tmp_path / "out"), "--reps", "50"]
    plain = CliRunner().invoke(_app(), args)
    assert plain.exit_code == 0, plain.output
    line = next(ln for ln in plain.output.splitlines() if ln.startswith("online_beats_drqv2_all"))
    assert NO_DATA in line and "runs reach 400 frames; the claim is about 1M frames" in line
    assert "indicative" not in line
    flagged = CliRunner().invoke(_app(), [*args, "--indicative"])
    assert flagged.exit_code == 0, flagged.output
    line = next(ln for ln in flagged.output.splitlines() if ln.startswith("online_beats_drqv2_all"))
    assert "indicative: TACO ahead on every task (400 frames, 2 seeds)" in line
    assert not any(ln.split()[1:2] in (["supported"], ["refuted"]) for ln in flagged.output.splitlines())
    table = pd.read_csv(tmp_path / "out" / "claims.csv", keep_default_na=False).set_index("id")
    assert table.loc["online_beats_drqv2_all", "verdict"] == NO_DATA
    assert table.loc["online_beats_drqv2_all", "indicative"].startswith("indicative: TACO ahead")


@pytest.mark.parametrize("text", [
    "frame,step,episode_reward\n0,0,1.5\n1000,500,2.5\n",
    "frame,step,episode_reward\n0,0\n",
    "frame,step,episode_reward\n0,0,1,4\n",
    "frame,step,episode_reward\n\n0,0,1\n",
    "\nframe,step\n0,0\n",
    "frame,step,episode_reward\n0,0,\"1,5\"\n",
    "frame,step,episode_reward\r\n0,0,1\r\n",
    "frame,step,episode_reward\n0,0,1\n0,1\n",
    ",\n,\n",
])
def test_csv_field_counts_are_the_csv_modules(text):
    """analysis.load reads unquoted run CSVs without the csv module: the same header and field counts."""
    import csv
    import io

    from analysis.load import _field_counts

    rows = list(csv.reader(io.StringIO(text)))
    assert _field_counts(text) == (rows[0], [len(r) for r in rows[1:]])


def test_train_speed_reads_only_its_columns_with_every_check(tmp_path):
    """_train_speed parses only frame, fps and critic_loss of train.csv: the same median FPS as a full read, and
    a short row or a non-numeric fps is still a problem."""
    from analysis.load import _fps_summary, _train_speed, read_csv_strict
    from repro.runs.runformat import TRAIN_REQUIRED

    path = tmp_path / "train.csv"
    path.write_text("frame,step,fps,note,critic_loss\n1000,500,40.0,x,\n2000,1000,50.0,y,0.5\n3000,1500,70.0,z,0.4\n")
    full = _fps_summary(read_csv_strict(path, TRAIN_REQUIRED))
    assert _train_speed(path, False, [])["fps"] == full == 60.0
    assert list(read_csv_strict(path, TRAIN_REQUIRED, only=("critic_loss",)).columns) == ["frame", "fps",
                                                                                         "critic_loss"]
    for bad in ("frame,step,fps\n1000,500,40.0\n2000,1000\n", "frame,step,fps\n1000,500,x\n"):
        path.write_text(bad)
        problems: list = []
        assert math.isnan(_train_speed(path, False, problems)["fps"]) and len(problems) == 1


def test_strict_csv_reader_checks_order_and_numbers_of_every_column_kind(tmp_path):
    """read_csv_strict's checks whatever pandas parsed a column as: integer, float or text frames reordered or
    repeated are refused, a non-numeric required value names its line, other text columns become NaN."""
    from analysis.load import read_csv_strict

    path = tmp_path / "eval.csv"
    refused = {"frame,score\n0,1\n20,2\n10,3\n": "not strictly increasing",
               "frame,score\n0,1\n10,2\n10,3\n": "not strictly increasing",
               "frame,score\n0.5,1\n0.25,2\n": "not strictly increasing",
               "frame,score\n0,1\n10,2\nx,3\n": "non-numeric or empty 'frame' at line 4",
               "frame,score\n0,1\n,2\n": "non-numeric or empty 'frame' at line 3"}
    for text, message in refused.items():
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            read_csv_strict(path, ("frame",))
    path.write_text("frame,score,note\n0,1,a\n10,x,b\n20.5,3,c\n")
    df = read_csv_strict(path, ("frame",), text_columns=("note",))
    assert list(df["frame"]) == [0.0, 10.0, 20.5] and df["frame"].dtype == float
    assert df["score"].isna().tolist() == [False, True, False] and list(df["note"]) == ["a", "b", "c"]
    path.write_text("frame,score\n5,1\n")
    assert len(read_csv_strict(path, ("frame",))) == 1
