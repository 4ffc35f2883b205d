"""Baseline calibration against the DrQ-v2 authors' published curves (analysis/calibration.py, issue 19).

Synthetic runs are written in the real run format (tests/analysis_fixtures.py ``write_run``: the evaluation
return ramps linearly from 0 to ``final`` over ``frames``, so a run's value at its last frame is ``final``).
The known published curve of the reading tests is a CSV in the published format written here.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest
import typer
from rliable import library as rly
from typer.testing import CliRunner

from analysis.audit import published_baseline
from analysis.calibration import (
    ABOVE,
    BELOW,
    CONSISTENT,
    NOT_ENOUGH,
    calibrate,
    packaged_published,
    write_calibration,
)
from analysis.claims import PUBLISHED_GAIN_ID, REFUTED, SUPPORTED, evaluate_claims
from analysis.context import Context
from analysis.load import PUBLISHED_DIR, SOURCE_PUBLISHED, SOURCE_RUNS, Results, load_published, load_results
from analysis.paper import DMC9, PaperData
from analysis_fixtures import write_run
from repro_app.analysis_cli import register

REPS = 300
REFERENCE = PUBLISHED_DIR  # hand values are read from the packaged CSVs with the csv module, not the loader
PUBLISHED_OFFSETS = (-20.0, -10.0, 0.0, 10.0, 20.0)  # five published seeds around a known curve


def write_published(folder: Path, task: str, slope: float = 0.01, end: int = 100_000) -> Path:
    """A published-format CSV: 5 seeds, evaluations every 20K frames, seed s at frame f = slope * f + offset."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [",agent,task,seed,frame,episode_reward,hour"]
    i = 0
    for s, off in enumerate(PUBLISHED_OFFSETS, start=1):
        for frame in range(0, end + 1, 20_000):
            lines.append(f"{i},DrQ-v2,{task},{s},{frame},{slope * frame + off},{frame / 1e5}")
            i += 1
    path = folder / f"dmc_{task}.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _drq_runs(root: Path, experiment: str, finals: list[float], frames: int = 50_000, task: str = "cheetah_run"):
    for seed, final in enumerate(finals):
        write_run(root, experiment=experiment, agent="drqv2", task=task, seed=seed, final=final, frames=frames,
                  eval_every=10_000)


# ---------------------------------------------------------------- packaging and loading
def test_published_curves_are_packaged_with_licence_and_loaded_apart_from_runs(tmp_path):
    assert (PUBLISHED_DIR / "LICENSE").read_text().startswith("MIT License")
    assert "facebookresearch/drqv2" in (PUBLISHED_DIR / "README.md").read_text()
    pyproject = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert 'repro_data = ["README.md", "paper/*", "reference/drqv2_curves/*"]' in pyproject
    provenance = (PUBLISHED_DIR.parents[1] / "README.md").read_text()
    assert "arXiv:2306.13229" in provenance and "MIT" in provenance and "c0c650b" in provenance
    pub = load_published()
    assert not pub.problems and set(DMC9) <= set(pub.runs["task"])
    assert set(pub.runs["source"]) == set(pub.eval["source"]) == {SOURCE_PUBLISHED}
    assert set(pub.runs["method"]) == {"DrQ-v2"} and pub.runs["run_id"].str.startswith("published/").all()
    # quadruped_run: 8 published seeds, one evaluation every 20K frames to 2.98M
    q = pub.eval[pub.eval["task"] == "quadruped_run"]
    assert q["run_id"].nunique() == 8 and len(q) == 8 * 150
    # each run's rows are its seed's rows of the file, in order, with its identity on every row
    raw = pd.read_csv(PUBLISHED_DIR / "dmc_quadruped_run.csv", index_col=0)
    seed = int(raw["seed"].max())
    mine = q[q["run_id"] == f"published/quadruped_run/seed{seed}"]
    part = raw[raw["seed"] == seed]
    assert mine["frame"].tolist() == part["frame"].astype(float).tolist()
    assert mine["episode_reward"].tolist() == part["episode_reward"].tolist()
    assert mine["step"].tolist() == (part["frame"] // 2).astype(float).tolist()
    assert mine["total_time"].tolist() == (part["hour"] * 3600.0).tolist()
    assert mine["episode"].tolist() == list(range(len(part))) and (mine["seed"] == seed).all()
    assert (mine["train_frames"] == part["frame"].max()).all() and mine["K"].isna().all()
    assert str(pub.eval["seed"].dtype) == str(pub.eval["episode"].dtype) == "int64"
    assert pub.eval["success"].isna().all() and pub.eval.index.equals(pd.RangeIndex(len(pub.eval)))
    _drq_runs(tmp_path, "main", [100.0, 110.0, 120.0])
    user = load_results(tmp_path)
    assert set(user.runs["source"]) == set(user.eval["source"]) == {SOURCE_RUNS}
    assert not user.runs["run_id"].str.startswith("published").any() and len(user.runs) == 3
    # a Results that mixes the two is refused, never calibrated
    mixed = Results(tmp_path, pd.concat([user.runs, pub.runs], ignore_index=True),
                    pd.concat([user.eval, pub.eval], ignore_index=True))
    with pytest.raises(ValueError, match="user's runs only"):
        calibrate(mixed, pub, reps=REPS)
    with pytest.raises(ValueError, match="load_published"):
        calibrate(user, user, reps=REPS)


def test_malformed_published_file_is_a_problem_not_a_crash(tmp_path):
    write_published(tmp_path / "pub", "cheetah_run")
    (tmp_path / "pub" / "dmc_walker_run.csv").write_text(",agent,task,seed,frame\n0,DrQ-v2,walker_run,1,0\n")
    pub = load_published(tmp_path / "pub")
    assert set(pub.runs["task"]) == {"cheetah_run"}
    assert len(pub.problems) == 1 and "episode_reward" in pub.problems[0].message


# ---------------------------------------------------------------- the three readings
def test_calibration_reads_below_consistent_and_above_a_known_curve(tmp_path):
    pub = load_published(write_published(tmp_path / "pub", "cheetah_run").parent)
    root = tmp_path / "runs"
    # the published curve at 50K frames (between its 40K and 60K evaluations): 0.01 * 50000 + offset = 500 +- 20
    _drq_runs(root, "low", [290.0, 300.0, 310.0])
    _drq_runs(root, "mid", [490.0, 500.0, 515.0])
    _drq_runs(root, "high", [690.0, 700.0, 710.0])
    _drq_runs(root, "two", [690.0, 700.0])
    rows, _ = calibrate(load_results(root), pub, reps=REPS)
    by = {r.experiment: r for r in rows}
    assert {e: r.reading for e, r in by.items()} == {"low": BELOW, "mid": CONSISTENT, "high": ABOVE,
                                                     "two": NOT_ENOUGH}
    for r in rows:
        assert r.frame == 50_000 and r.published_n == 5
        assert r.published_mean == pytest.approx(500.0)  # interpolated halfway between 400 and 600
    assert by["low"].user_mean == pytest.approx(300.0) and by["low"].diff == pytest.approx(-200.0)
    assert by["low"].diff_ci_high < 0 < by["high"].diff_ci_low
    assert by["mid"].diff_ci_low < 0 < by["mid"].diff_ci_high
    assert "user has 2 seeds" in by["two"].note and np.isnan(by["two"].diff_ci_low)


def test_calibration_of_runs_with_shorter_episodes_is_not_comparable(tmp_path):
    """A DrQ-v2 of 100-frame episodes (profile=tiny) held against the 1000-frame published curves: its values are
    shown, named by the difference, with no Δ and no below/above reading."""
    from analysis.calibration import OTHER_ENV, calibration_frames

    pub = load_published(write_published(tmp_path / "pub", "cheetah_run").parent)
    for seed, final in enumerate([30.0, 31.0, 32.0]):
        write_run(tmp_path / "runs", experiment="tiny", agent="drqv2", task="cheetah_run", seed=seed, final=final,
                  frames=50_000, eval_every=10_000, config={"env.max_episode_frames": 100})
    (row,), _ = calibrate(load_results(tmp_path / "runs"), pub, reps=REPS)
    assert row.reading == OTHER_ENV and np.isnan(row.diff) and np.isnan(row.diff_ci_low)
    assert row.user_mean == pytest.approx(31.0) and "100-frame episodes (paper: 1,000)" in row.note
    shown = calibration_frames([row])[1].iloc[0]
    assert shown["Reading"] == OTHER_ENV and shown["Env. frames (action repeat 2)"] == "50,000 frames"
    assert shown["Δ [95% CI]"] == "n/a"


def test_calibration_at_the_runs_own_budget_and_capped_at_the_curves_end(tmp_path):
    pub = load_published(write_published(tmp_path / "pub", "cheetah_run", end=60_000).parent)
    root = tmp_path / "runs"
    _drq_runs(root, "short", [300.0, 310.0, 320.0], frames=30_000)  # budget 30K: published 300 +- 20
    _drq_runs(root, "long", [600.0, 600.0, 600.0], frames=100_000)  # past the curve's end (60K): read at 60K
    rows = {r.experiment: r for r in calibrate(load_results(root), pub, reps=REPS)[0]}
    assert rows["short"].frame == 30_000 and rows["short"].published_mean == pytest.approx(300.0)
    assert rows["short"].reading == CONSISTENT
    assert rows["long"].frame == 60_000 and rows["long"].user_mean == pytest.approx(360.0)
    assert "published curve ends at 60,000 frames" in rows["long"].note
    # --frames: an earlier frame of the user's choice (the runs ramp linearly: 600 * 10K / 100K = 60 at 10K)
    rows = {r.experiment: r for r in calibrate(load_results(root), pub, reps=REPS, at=10_000)[0]}
    assert rows["long"].frame == 10_000 and rows["long"].user_mean == pytest.approx(60.0)
    assert rows["long"].published_mean == pytest.approx(100.0) and rows["long"].note == ""
    rows = {r.experiment: r for r in calibrate(load_results(root), pub, reps=REPS, at=50_000)[0]}
    assert rows["short"].frame == 30_000 and "asked for 50,000 frames; runs reach 30,000 frames" in rows["short"].note


def test_calibration_table_is_written_as_csv_markdown_latex(tmp_path):
    pub = load_published(write_published(tmp_path / "pub", "cheetah_run").parent)
    _drq_runs(tmp_path / "runs", "main", [290.0, 300.0, 310.0])
    rows, notes = calibrate(load_results(tmp_path / "runs"), pub, reps=REPS)
    table = write_calibration(tmp_path / "out", rows, notes, REPS, 0)
    assert [p.name for p in table.files] == ["calibration.csv", "calibration.md", "calibration.tex"]
    raw = pd.read_csv(tmp_path / "out" / "calibration.csv")
    assert raw.loc[0, "reading"] == BELOW and raw.loc[0, "user_n"] == 3
    md = (tmp_path / "out" / "calibration.md").read_text()
    assert "not a claim of the paper" in md and "linearly interpolated" in md and "random state 0" in md


# ---------------------------------------------------------------- audit of the paper's DrQ-v2 cells
def _hand_1m(task: str) -> np.ndarray:
    """The published seeds' returns at exactly 1M frames, read with the csv module (1M is a grid point)."""
    with open(REFERENCE / f"dmc_{task}.csv", newline="") as fh:
        return np.array([float(r["episode_reward"]) for r in csv.DictReader(fh) if r["frame"] == "1000000"])


def _rliable_ci(task: str, reps: int) -> tuple[float, float]:
    """rliable's own 95% CI of the mean for ``task``, bootstrapped as analysis.stats documents: the DMC9 tasks with
    the same number of published seeds together, as the columns of one (seeds x tasks) matrix, random state 0."""
    by_n: dict[int, list[str]] = {}
    for t in DMC9:
        by_n.setdefault(len(_hand_1m(t)), []).append(t)
    group = by_n[len(_hand_1m(task))]
    matrix = np.stack([_hand_1m(t) for t in group], axis=1)
    state = np.random.get_state()
    np.random.seed(0)
    _, cis = rly.get_interval_estimates({"x": matrix}, lambda x: np.mean(x, axis=0), reps=reps,
                                        random_state=np.random.RandomState(0))
    np.random.set_state(state)
    j = group.index(task)
    return float(cis["x"][0][j]), float(cis["x"][1][j])


def test_audit_rows_from_packaged_data_match_a_hand_computation():
    reps = 2_000
    findings = {f.description.split(":")[0]: f for f in published_baseline(PaperData(), reps=reps)}
    # hand values (csv module on the packaged CSVs): quadruped_run has 8 seeds at 1M with mean
    # 459.486; reacher_hard 10 seeds with mean 705.94; Table 1 prints 407 and 572 for DrQ-v2
    quad, reach = _hand_1m("quadruped_run"), _hand_1m("reacher_hard")
    assert len(quad) == 8 and quad.mean() == pytest.approx(459.48588539636756)
    assert len(reach) == 10 and reach.mean() == pytest.approx(705.94)
    for task, values, paper in (("quadruped_run", quad, 407.0), ("reacher_hard", reach, 572.0)):
        f = findings[task]
        lo, hi = _rliable_ci(task, reps)
        m = re.match(r"published ([\d.]+) \[([\d.]+), ([\d.]+)\] \(n=(\d+)\); paper (\w+) the CI(?: by ([\d.]+))?",
                     f.recomputed)
        assert m, f.recomputed
        assert float(m.group(1)) == pytest.approx(values.mean(), abs=0.05) and int(m.group(4)) == len(values)
        assert float(m.group(2)) == pytest.approx(lo, abs=0.05) and float(m.group(3)) == pytest.approx(hi, abs=0.05)
        assert f.match == (lo <= paper <= hi) and f.printed.startswith(f"{paper:g} ±")
        if not f.match:
            assert m.group(5) == "below" and float(m.group(6)) == pytest.approx(lo - paper, abs=0.05)
    # the abstract's ratio with the published baseline: Table 1's TACO 9-task mean over the mean of the published
    # per-task means at 1M
    t1 = PaperData().online.pivot(index="task", columns="method", values="mean")
    hand = t1.loc[list(DMC9), "TACO"].mean() / np.mean([_hand_1m(t).mean() for t in DMC9])
    ratio = findings["TACO / DrQ-v2 ratio of the 9-task means"]
    assert ratio.printed.startswith("1.397x")
    assert ratio.recomputed.startswith(f"{hand:.3f}x")


# ---------------------------------------------------------------- online_avg_gain against the published curves
def _taco_grid(root: Path, factor: float, frames: int, pub: Results, agent: str = "taco") -> None:
    from analysis.calibration import published_values

    for task in DMC9:
        base = float(np.mean(published_values(pub, task, frames)))
        for seed in range(3):
            write_run(root, experiment="main", agent=agent, task=task, seed=seed, final=factor * base + seed,
                      frames=frames, eval_every=frames // 2)


def test_online_avg_gain_read_against_the_published_curves(tmp_path):
    pub = packaged_published()
    _taco_grid(tmp_path / "taco", 1.5, 1_000_000, pub)
    ctx = Context(results=load_results(tmp_path / "taco"), out_dir=tmp_path / "out", reps=REPS)
    verdicts = {v.id: v for v in evaluate_claims(ctx)}
    own, published = verdicts["online_avg_gain"], verdicts[PUBLISHED_GAIN_ID]
    assert own.verdict not in (SUPPORTED, REFUTED)  # no DrQ-v2 runs of one's own
    assert published.verdict == SUPPORTED and "published" in published.claim
    r = float(re.search(r"= ([\d.]+) \(95% CI", published.evidence).group(1))
    assert r == pytest.approx(1.5 + 1.0 / np.mean([np.mean(_hand_1m(t)) for t in DMC9]), abs=2e-3)
    # with DrQ-v2 runs of one's own, both readings
    _taco_grid(tmp_path / "taco", 1.0, 1_000_000, pub, agent="drqv2")
    ctx = Context(results=load_results(tmp_path / "taco"), out_dir=tmp_path / "out", reps=REPS)
    verdicts = {v.id: v for v in evaluate_claims(ctx)}
    assert verdicts["online_avg_gain"].verdict == SUPPORTED and verdicts[PUBLISHED_GAIN_ID].verdict == SUPPORTED


def test_online_avg_gain_vs_published_keeps_the_claims_budget_rule(tmp_path):
    pub = packaged_published()
    _taco_grid(tmp_path / "taco", 0.9, 100_000, pub)  # 100K frames: below the claim's 1M
    ctx = Context(results=load_results(tmp_path / "taco"), out_dir=tmp_path / "out", reps=REPS, indicative=True)
    v = {v.id: v for v in evaluate_claims(ctx)}[PUBLISHED_GAIN_ID]
    assert v.verdict not in (SUPPORTED, REFUTED) and "the claim is about 1M frames" in v.evidence
    assert v.indicative.startswith("indicative: TACO under 1.3x DrQ-v2 (100,000 frames")


# ---------------------------------------------------------------- figures
def _image(path: Path) -> np.ndarray:
    return mpimg.imread(path)[..., :3]


def test_f4_draws_the_published_band_and_a_switch_hides_it(tmp_path):
    from paper_figures.f4_curves_dmc import render

    root = tmp_path / "runs"
    for seed in range(2):
        write_run(root, experiment="main", agent="taco", task="quadruped_run", seed=seed, final=400.0 + seed,
                  frames=100_000, eval_every=20_000)
    results = load_results(root)
    shown = render(Context(results=results, out_dir=tmp_path / "with", curve_reps=50))
    hidden = render(Context(results=results, out_dir=tmp_path / "without", curve_reps=50, published_band=False))
    assert "published by its authors" in shown.caption and "facebookresearch/drqv2" in shown.caption
    assert "published" not in hidden.caption
    a, b = _image(shown.figures[0]), _image(hidden.figures[0])
    assert a.var() > 1e-3 and (a.shape != b.shape or np.abs(a - b).max() > 0.1)


def test_repro_plot_draws_the_published_band_and_no_published_hides_it(tmp_path):
    root = tmp_path / "runs"
    for seed in range(2):
        write_run(root, experiment="main", agent="drqv2", task="cheetah_run", seed=seed, final=300.0 + seed,
                  frames=100_000, eval_every=20_000)
    app = typer.Typer()
    from repro_app import watch_cli

    watch_cli.register(app)
    runner = CliRunner()
    with_band = runner.invoke(app, ["plot", str(root), "--out", str(tmp_path / "a.png"), "--reps", "50"])
    without = runner.invoke(app, ["plot", str(root), "--out", str(tmp_path / "b.png"), "--reps", "50",
                                  "--no-published"])
    assert with_band.exit_code == 0 and without.exit_code == 0, with_band.output + without.output
    a, b = _image(tmp_path / "a.png"), _image(tmp_path / "b.png")
    assert a.shape != b.shape or np.abs(a - b).max() > 0.1


# ---------------------------------------------------------------- CLI
def _app() -> typer.Typer:
    app = typer.Typer()
    register(app)
    return app


def test_cli_calibrate_bad_results_is_one_line_exit_2():
    result = CliRunner().invoke(_app(), ["calibrate", "--results", "/nonexistent/root"])
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and "does not exist" in lines[0]
    assert "Traceback" not in result.output


def test_cli_calibrate_writes_the_table(tmp_path):
    _drq_runs(tmp_path / "runs", "main", [150.0, 160.0, 170.0], frames=100_000, task="quadruped_run")
    result = CliRunner().invoke(_app(), ["calibrate", "--results", str(tmp_path / "runs"), "--out",
                                         str(tmp_path / "out"), "--reps", str(REPS)])
    assert result.exit_code == 0, result.output
    assert "not a claim of the paper" in result.output and "quadruped_run" in result.output
    raw = pd.read_csv(tmp_path / "out" / "calibration.csv")
    # published quadruped_run at 100K (a grid point): hand mean of its 8 seeds
    with open(REFERENCE / "dmc_quadruped_run.csv", newline="") as fh:
        hand = np.mean([float(r["episode_reward"]) for r in csv.DictReader(fh) if r["frame"] == "100000"])
    assert raw.loc[0, "frame"] == 100_000 and raw.loc[0, "published_mean"] == pytest.approx(hand)
    assert raw.loc[0, "user_mean"] == pytest.approx(160.0)


def test_report_has_the_calibration_and_published_audit_sections(tmp_path):
    from repro_app.report import build_markdown

    pub = load_published(write_published(tmp_path / "pub", "cheetah_run").parent)
    _drq_runs(tmp_path / "runs", "main", [290.0, 300.0, 310.0])
    ctx = Context(results=load_results(tmp_path / "runs"), out_dir=tmp_path / "out", reps=REPS)
    findings = published_baseline(PaperData(), reps=REPS)
    md = build_markdown(ctx, [], [], findings, calibrate(ctx.results, pub, reps=REPS))
    cal = md.split("## Baseline calibration", 1)[1].split("\n## ", 1)[0]
    assert "| Cheetah Run |" not in cal and "| cheetah_run | main/base | 50,000 frames |" in cal
    assert "| below |" in cal and "not a claim of the paper" in cal
    audit = md.split("## Audit: the paper's DrQ-v2 baseline against the published curves", 1)[1].split("\n## ", 1)[0]
    assert "of 9 of the paper's DrQ-v2 cells" in audit and "OUTSIDE published CI" in audit
    assert "TACO / DrQ-v2 ratio" in audit
