"""`repro verify` (issue 33): the verdict against the DrQ-v2 authors' published curves on synthetic runs, its
false-alarm rate, the random-policy reference, the sweep's expansion, and a tiny end-to-end run of the command.

Synthetic runs are written in the real run format (tests/analysis_fixtures.py ``write_run`` with ``curve``: the
evaluation returns at frames 0, 20K, 40K, 60K). The published band of cartpole_balance (packaged curves, 10 seeds) is
[-0.8, 628.5] at 20K, [226.5, 1187.7] at 40K and [952.7, 1004.7] at 60K frames.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from analysis import verify as V
from analysis.load import load_results
from analysis_fixtures import write_run
from repro.envs.dmc import DMCEnv, random_policy_returns
from repro.envs.registry import get_task
from repro.launch import spec as specs
from repro.runs import runformat

TASK = "cartpole_balance"
RANDOM = {TASK: 300.0}  # the random-policy reference, fixed so that the thresholds below are known


def _runs(root: Path, agent: str, curves: list[list[float]], eval_every: int = 20_000) -> None:
    for seed, curve in enumerate(curves, start=1):
        write_run(root, experiment="verify", agent=agent, task=TASK, seed=seed, final=0.0,
                  frames=eval_every * (len(curve) - 1), eval_every=eval_every, curve=curve, batch_size=256)


def _judge(root: Path, **kw) -> dict[str, V.VerdictRow]:
    return {r.method: r for r in V.judge(load_results(root), random_returns=RANDOM, **kw)}


def test_band_and_false_alarm_rate_by_hand():
    # four published seeds at one frame: 0, 10, 20, 30 (sd of any three of them: 10)
    pub = np.array([[0.0], [10.0], [20.0], [30.0]])
    assert V.band(pub[:, 0], k=0) == (0.0, 30.0)
    # k=0: leaving out 0 gives the band [10, 30] (0 outside), leaving out 30 gives [0, 20] (30 outside): 2 of 4
    assert V.false_alarm_rate(pub, 1, k=0) == 0.5
    # k=1: the band of the other three is their range +- 10: every left-out seed is inside
    assert V.false_alarm_rate(pub, 1, k=1) == 0.0
    # two seeds: the means of {0,10}, {0,20}, ... against the range of the other two +- their sd
    rest_sd = np.std([20.0, 30.0], ddof=1)
    assert (np.mean([0.0, 10.0]) < 20.0 - rest_sd) and V.false_alarm_rate(pub, 2, k=1) > 0
    assert np.isnan(V.false_alarm_rate(pub, 3))  # a band needs two published seeds left


def test_cartpole_false_alarm_rate_from_the_published_seeds():
    frames = V.published_frames(TASK, 60_000)
    assert frames == [20_000, 40_000, 60_000]
    pub = V.published_matrix(TASK, frames)
    assert pub.shape == (10, 3)
    # one published seed (1: 135.5 / 738.0 / 962.8) is under the band of the other nine at 60K (their min 973.7
    # minus their sd 6.9): 1 of 10, the rate docs/verification.md states
    assert V.false_alarm_rate(pub, 1) == pytest.approx(0.1)


def test_drqv2_inside_the_band_learns_as_published(tmp_path):
    _runs(tmp_path, "drqv2", [[350, 300, 800, 980]])
    row = _judge(tmp_path)["DrQ-v2"]
    assert row.verdict == V.LEARNS
    assert [f.frame for f in row.frames] == [20_000, 40_000, 60_000]
    assert [f.position for f in row.frames] == [V.INSIDE] * 3
    assert row.false_alarm == pytest.approx(0.1)


def test_drqv2_stuck_is_below_the_band(tmp_path):
    _runs(tmp_path, "drqv2", [[350, 135, 135, 135], [350, 140, 150, 160]])
    row = _judge(tmp_path)["DrQ-v2"]
    assert row.verdict == V.BELOW
    assert [f.position for f in row.frames] == [V.INSIDE, V.UNDER, V.UNDER]
    assert "40,000 frames" in row.note and "60,000 frames" in row.note
    assert row.seeds == 2 and row.frames[1].mean == pytest.approx(142.5)


def test_drqv2_over_the_band_is_above(tmp_path):
    _runs(tmp_path, "drqv2", [[350, 900, 990, 990]])
    row = _judge(tmp_path)["DrQ-v2"]
    assert row.verdict == V.ABOVE and row.frames[0].position == V.OVER


def test_too_short_or_too_few_is_not_enough_data(tmp_path):
    _runs(tmp_path / "short", "drqv2", [[350, 135, 135]])  # stuck, but only to 40K: no verdict yet
    row = _judge(tmp_path / "short")["DrQ-v2"]
    assert row.verdict == V.NOT_ENOUGH and "60,000 frames" in row.note
    assert [f.position for f in row.frames] == [V.INSIDE, V.UNDER]  # the frames are still shown
    _runs(tmp_path / "few", "drqv2", [[350, 300, 800, 980]])
    row = _judge(tmp_path / "few", min_seeds=2)["DrQ-v2"]
    assert row.verdict == V.NOT_ENOUGH and "1 seed(s)" in row.note
    # one seed of two unfinished: the cell is read where every seed is
    _runs(tmp_path / "mixed", "drqv2", [[350, 300, 800, 980]])
    write_run(tmp_path / "mixed", experiment="verify", agent="drqv2", task=TASK, seed=2, final=0.0, frames=40_000,
              eval_every=20_000, curve=[350, 300, 800], done=False)
    row = _judge(tmp_path / "mixed")["DrQ-v2"]
    assert row.verdict == V.NOT_ENOUGH and row.reached == 40_000


def test_taco_learned_against_the_random_policy(tmp_path):
    # threshold at 40K: 300 + 0.5 * (834.9 - 300) = 567.5
    _runs(tmp_path / "yes", "taco", [[350, 300, 700]])
    row = _judge(tmp_path / "yes")["TACO"]
    assert row.verdict == V.LEARNED and row.threshold == pytest.approx(300 + 0.5 * (834.87 - 300), abs=0.1)
    _runs(tmp_path / "no", "taco", [[350, 300, 500]])
    assert _judge(tmp_path / "no")["TACO"].verdict == V.NOT_LEARNED
    _runs(tmp_path / "early", "taco", [[350, 900]])
    assert _judge(tmp_path / "early")["TACO"].verdict == V.NOT_ENOUGH


def test_taco_against_the_published_seeds_by_hand(tmp_path):
    """P(X > Y) of TACO's seeds over the published DrQ-v2 seeds at each judged frame, counted by hand: at 20K the
    published seeds are 135, 136, 360, 365, 373, 450, 474, 477, 485, 492; 400 beats 5 of them and 480 beats 8:
    (5 + 8) / 20 = 0.65. At 40K (429 ... 985) 990 beats all ten and 500 beats one: 11 / 20. DrQ-v2 has none."""
    _runs(tmp_path, "taco", [[350, 400, 990], [350, 480, 500]])
    _runs(tmp_path, "drqv2", [[350, 400, 990]])
    rows = _judge(tmp_path)
    adv = rows["TACO"].advantage
    assert [(a.frame, a.n, a.published_n) for a in adv] == [(20_000, 2, 10), (40_000, 2, 10)]
    assert adv[0].poi == pytest.approx(0.65) and adv[1].poi == pytest.approx(0.55)
    assert all(a.poi_low <= a.poi <= a.poi_high and a.poi_low < a.poi_high for a in adv)
    assert rows["DrQ-v2"].advantage == []
    tables = V.advantage_frame(list(rows.values()))
    assert list(tables["method"]) == ["TACO", "TACO"]
    assert "not a verdict" in V.advantage_lines(list(rows.values()))[0]


def _saturated_train_csv(run: Path, episodes: int = 15) -> None:
    """The run's train.csv as a run whose actor saturated after its seed frames writes it (1000-frame episodes)."""
    from analysis_fixtures import METRICS
    from repro.runs.logger import format_row, header_line

    columns = runformat.train_columns(METRICS)
    rows = [header_line(columns)]
    for i in range(1, episodes + 1):
        rows.append(format_row(columns, {"frame": i * 1000, "step": i * 500, "episode": i, "episode_reward": 160.0,
                                         "episode_length": 1000, "buffer_size": i * 500, "stddev": 0.9, "fps": 5.0,
                                         "total_time": float(i), **{m: None if i <= 4 else 1.0 for m in METRICS}}))
    (run / runformat.TRAIN).write_text("".join(rows))


def test_a_saturated_seed_is_named_beside_its_verdict_and_in_the_report(tmp_path):
    from repro_app.report import _verify_section

    _runs(tmp_path, "taco", [[350, 136, 136], [350, 900, 990]])
    dead = next(tmp_path.glob("verify/taco/base/cartpole_balance/seed_1"))
    _saturated_train_csv(dead)
    _runs(tmp_path, "drqv2", [[350, 400, 990]])
    rows = V.judge(load_results(tmp_path), random_returns=RANDOM)
    taco = next(r for r in rows if r.method == "TACO")
    assert taco.health == "seed 1: actor saturated since frame 4,000: its policy gradient is zero"
    assert V.health_text(next(r for r in rows if r.method == "DrQ-v2")) == "not saturated"
    # a seed at the bound for a shorter stretch so far is named as such, not "not saturated"
    _saturated_train_csv(next(tmp_path.glob("verify/drqv2/base/cartpole_balance/seed_1")), episodes=7)
    drq = next(r for r in V.judge(load_results(tmp_path), random_returns=RANDOM) if r.method == "DrQ-v2")
    assert V.health_text(drq) == ("seed 1: actor at the bound since frame 4,000: 3,000 of the 10,000 frames that make "
                                  "it saturated")
    assert taco.health in next(line for line in V.verdict_lines(rows) if "TACO" in line)
    section = _verify_section(rows)
    assert "seed 1: actor saturated since frame 4,000" in section and "Early advantage" in section
    assert "Environment frames (action repeat 2)" in section and "| 20,000 frames |" in section  # with its unit
    V.write_verdicts(tmp_path / "out", rows)
    assert "actor saturated since frame 4,000" in (tmp_path / "out" / "verify.md").read_text()


def test_only_the_verify_experiment_is_judged(tmp_path):
    write_run(tmp_path, experiment="main", agent="drqv2", task=TASK, seed=1, final=0.0, frames=60_000,
              eval_every=20_000, curve=[350, 135, 135, 135])
    write_run(tmp_path, experiment="verify", agent="drqv2", task="cheetah_run", seed=1, final=500.0)
    assert V.judge(load_results(tmp_path), random_returns=RANDOM) == []


def test_write_verdicts_and_figure(tmp_path):
    from paper_figures.verify_plot import plot_verify

    _runs(tmp_path, "drqv2", [[350, 300, 800, 980]])
    _runs(tmp_path, "taco", [[350, 300, 500]])
    results = load_results(tmp_path)
    judged = V.judgement(results, random_returns=RANDOM)
    rows = judged.rows
    verdicts, frames = V.write_verdicts(tmp_path / "out", rows)
    table = pd.read_csv(tmp_path / "out" / "verify.csv")
    assert list(table["verdict"]) == [V.LEARNS, V.NOT_LEARNED]
    assert len(pd.read_csv(tmp_path / "out" / "verify_frames.csv")) == 5
    assert "False alarm" in (tmp_path / "out" / "verify.md").read_text()
    paths = plot_verify(results, judged, tmp_path / "out")
    assert [p.suffix for p in paths] == [".png", ".pdf"] and all(p.stat().st_size > 5000 for p in paths)


def _episodes(root: Path, frames: int) -> None:
    """Every run under ``root`` configured with episodes of ``frames`` frames (profile=tiny's 100)."""
    from omegaconf import OmegaConf

    for path in root.rglob(runformat.CONFIG):
        cfg = OmegaConf.load(path)
        cfg.env.max_episode_frames = frames
        OmegaConf.save(cfg, path)


def test_the_verdict_table_states_its_statistic_band_and_false_alarm(tmp_path):
    """Every row of verify.md carries the statistic the rule reads, the band (or the threshold) and the false-alarm
    rate, as numbers where they exist and "n/a: <why>" where they do not; never an empty cell or a dash there."""
    _runs(tmp_path / "done", "drqv2", [[350, 300, 800, 980]])
    _runs(tmp_path / "done", "taco", [[350, 300, 700]])
    _runs(tmp_path / "short", "drqv2", [[350, 300]])
    _runs(tmp_path / "short", "taco", [[350, 300]])
    rows = _judge(tmp_path / "done")
    drq, taco = rows["DrQ-v2"], rows["TACO"]
    assert drq.statistic == "mean of 1 seed(s): 300.0 at 20,000 frames; 800.0 at 40,000 frames; 980.0 at 60,000 frames"
    assert drq.band == ("[-0.8, 628.5] at 20,000 frames; [226.5, 1187.7] at 40,000 frames; [952.7, 1004.7] at "
                        "60,000 frames")
    assert V.false_alarm_text(drq) == "10% for 1 seed(s)"
    assert taco.statistic.startswith("mean of 1 seed(s): 700.0 at 40,000 frames")
    assert taco.band.startswith(">= 567.4 at 40,000 frames = random 300.0 + 0.5 x (published DrQ-v2 834.9")
    assert V.false_alarm_text(taco).startswith("n/a: the learned rule reads a threshold")
    short = _judge(tmp_path / "short")
    assert short["DrQ-v2"].statistic == "mean of 1 seed(s): 300.0 at 20,000 frames (so far)"
    assert V.false_alarm_text(short["DrQ-v2"]) == "0% for 1 seed(s) (at the frames reached so far)"  # 20K alone
    assert short["TACO"].band.startswith("n/a: the threshold is set once every seed reaches 40,000 frames")
    # more seeds than the published ten leave room for: no rate, and the reason
    many = V.VerdictRow(**{**drq.__dict__, "seeds": 9, "false_alarm": float("nan")})
    assert V.false_alarm_text(many) == ("n/a: the rate needs 9 + 2 published seeds (one set judged against a band of "
                                        "at least two others); 10 are published")
    for root in ("done", "short"):
        V.write_verdicts(tmp_path / root / "out", list(_judge(tmp_path / root).values()))
        table = V.verdict_display(list(_judge(tmp_path / root).values()))
        for col in ("Statistic", "Band (DrQ-v2) / threshold (others)", "False alarm"):
            assert all(v and v not in ("—", "-", "nan") for v in table[col]), (root, col, list(table[col]))
        md = (tmp_path / root / "out" / "verify.md").read_text()
        assert "| Statistic | Band (DrQ-v2) / threshold (others) | False alarm |" in md and "—" not in md
    assert "| 10% for 1 seed(s) |" in (tmp_path / "done" / "out" / "verify.md").read_text()


def test_a_run_with_other_episodes_says_so_and_gets_no_verdict(tmp_path):
    """profile=tiny's 100-frame episodes (the published curves': 1000) return about a tenth of the published
    returns: named in the row, the frames table, the terminal line and the figure's title; a run long enough for a
    verdict is 'not comparable' (exit 0), a short one stays 'not enough data' and says so."""
    from paper_figures.verify_plot import draw_panel

    _runs(tmp_path / "long", "drqv2", [[99, 40, 38, 38]])
    _runs(tmp_path / "long", "taco", [[99, 40, 38]])
    _episodes(tmp_path / "long", 100)
    rows = _judge(tmp_path / "long")
    text = "100-frame episodes (published: 1,000)"
    assert rows["DrQ-v2"].verdict == V.NOT_COMPARABLE and rows["TACO"].verdict == V.NOT_COMPARABLE
    assert all(r.environment == text and not r.judged for r in rows.values())
    assert text in rows["DrQ-v2"].note and "1000-frame episodes" in rows["DrQ-v2"].note
    assert rows["TACO"].band.startswith("n/a") and V.false_alarm_text(rows["DrQ-v2"]) == "10% for 1 seed(s)"
    assert all(text in line for line in V.verdict_lines(list(rows.values())))
    V.write_verdicts(tmp_path / "out", list(rows.values()))
    md = (tmp_path / "out" / "verify.md").read_text()
    assert f"| {text}: not comparable | not comparable |" in md and "2 not comparable" in md
    assert f"below (not comparable: {text})" in (tmp_path / "out" / "verify_frames.md").read_text()

    _runs(tmp_path / "tiny", "drqv2", [[99, 60, 38]], eval_every=200)
    _episodes(tmp_path / "tiny", 100)
    results = load_results(tmp_path / "tiny")
    row = V.judge(results, random_returns=RANDOM)[0]
    assert row.verdict == V.NOT_ENOUGH and row.environment == text and "'not comparable'" in row.note
    fig, ax = plt.subplots()
    draw_panel(ax, results, V.verify_cells(results), TASK, [row])
    assert text in ax.get_title()
    plt.close(fig)
    # the published settings, written out as a config does, are no difference
    cfg = {"env": {"max_episode_frames": 1000, "action_repeat": 2, "image_size": 84, "frame_stack": 3,
                   "distracting_dims": 0, "camera": 0}}
    assert V.environment_differences(cfg, TASK) == []
    cfg["env"].update(action_repeat=4, camera=1)
    assert V.environment_differences(cfg, TASK) == ["action repeat 4 (published: 2)", "camera 1 (published: 0)"]


@pytest.mark.parametrize("curve, eval_every, band", [([99, 60, 38], 200, False), ([350, 300, 800, 980], 20_000, True)])
def test_the_figure_ends_at_the_data_and_its_legend_lists_what_is_drawn(tmp_path, curve, eval_every, band):
    """A 400-frame run: the x axis ends at 400 frames (not at the published 20K), and no verdict band is listed (no
    published frame after 0 is reached, so none is drawn); a 60K run: the band is drawn at 20K, 40K and 60K and
    listed once."""
    from paper_figures.verify_plot import draw_panel

    _runs(tmp_path, "drqv2", [curve], eval_every=eval_every)
    results = load_results(tmp_path)
    rows = V.judge(results, random_returns=RANDOM)
    fig, ax = plt.subplots()
    draw_panel(ax, results, V.verify_cells(results), TASK, rows)
    last = eval_every * (len(curve) - 1)
    assert last < ax.get_xlim()[1] <= 1.05 * last
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("verdict band" in t for t in labels) is band
    assert len(labels) == len(set(labels)) == 3 + band
    assert "action repeat 2" in ax.get_xlabel()
    if band:
        caps = [c for c in ax.containers if c.get_label().startswith("verdict band")]
        assert len(caps) == 1 and len(caps[0].lines[2][0].get_segments()) == 3  # one bar per judged frame
    plt.close(fig)


def test_random_policy_returns_equal_the_pixel_env():
    """The simulator-only random rollout sums rewards as the pixel environment does (same actions, same seed)."""
    info = get_task(TASK)
    fast = random_policy_returns(info, 1, seed=3, action_repeat=20)
    env = DMCEnv(info, seed=0, action_repeat=20, image_size=16)
    rng = np.random.default_rng(3)
    ts, total = env.reset(seed=0), 0.0
    while not ts.last:
        ts = env.step(rng.uniform(-1.0, 1.0, size=(1,)))
        total += ts.reward
    assert fast == [pytest.approx(total, rel=1e-12)]
    assert 0 < total < 1000


def test_the_verify_sweep_expands_to_the_check():
    spec = specs.load("verify")
    planned = specs.plan(specs.expand(spec, specs.Selection(sets=("runtime.results_root=/nonexistent",))))
    base = [(a, s) for a in ("alix", "drqv2", "taco") for s in (1, 2, 3)]
    assert sorted((p.run.agent, p.run.variant, p.run.seed) for p in planned) == sorted(
        [(a, "base", s) for a, s in base] + [("drqv2", "plain", 1)])  # the default path: DrQ-v2 seed 1
    for p in planned:
        cfg = p.cfg
        assert (cfg.task.name, cfg.train.frames, cfg.train.eval_every_frames, cfg.train.eval_episodes) == \
            (TASK, 60_000, 20_000, 10)
        assert cfg.agent.batch_size == 256 and cfg.agent.fast is (p.run.variant == "base") and cfg.agent.nstep == 3
        # DrQ-v2's easy schedule: std linear(1.0, 0.1, 100000) in agent steps
        assert dict(cfg.agent.stddev_schedule) == {"start": 1.0, "end": 0.1, "duration": 100_000, "step_scale": 1}
        assert cfg.env.action_repeat == 2
        assert cfg.experiment == "verify"


def _verify(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "repro", "verify", *args], capture_output=True, text=True,
                          timeout=600)


def test_one_cpu_time_for_the_check_everywhere():
    """The CPU check's time is one figure: the one `repro verify` prints on a machine without a GPU, repeated by the
    README and docs/verification.md (three different times were quoted before issue 49)."""
    from repro_app.verify_cli import CPU_CHECK_TIME

    root = Path(__file__).resolve().parents[1]
    for doc in ("README.md", "docs/verification.md"):
        assert CPU_CHECK_TIME in " ".join((root / doc).read_text().split()), doc


def test_verify_bad_input_is_one_line(tmp_path):
    out = _verify("--agents", "dreamer", "-r", str(tmp_path), "--dry-run")
    assert out.returncode == 2 and "Traceback" not in out.stderr + out.stdout
    assert "the verify sweep has drqv2, taco, alix" in out.stderr + out.stdout
    out = _verify("--variants", "bf16", "-r", str(tmp_path), "--dry-run")
    assert out.returncode == 2 and "the verify sweep has base, plain" in out.stderr + out.stdout


@pytest.mark.slow
def test_verify_tiny_end_to_end(tmp_path):
    """`repro verify --set profile=tiny`: the profile's budget, evaluation and batch win over the sweep's, the runs
    train through the local launcher (warm start), every verdict is 'not enough data', the tables and the figure are
    written; run again, it trains nothing and judges again."""
    import torch

    dry = _verify("--set", "profile=tiny", "-r", str(tmp_path / "runs"), "--dry-run")
    assert dry.returncode == 0, dry.stderr
    if not torch.cuda.is_available():
        assert "no GPU: agents drqv2, variants base, seeds 1..1" in dry.stdout
    assert "train.frames=400" in dry.stdout and "agent.batch_size=8" in dry.stdout  # the profile's, after the sweep's
    args = ("--set", "profile=tiny", "--frames", "200", "--agents", "drqv2,taco", "--seeds", "1",
            "-r", str(tmp_path / "runs"), "-o", str(tmp_path / "out"), "--keep-runs")
    out = _verify(*args)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith(TASK)]
    assert len(lines) == 2 and all(V.NOT_ENOUGH in line for line in lines), out.stdout
    table = pd.read_csv(tmp_path / "out" / "verify.csv")
    assert sorted(table["method"]) == ["DrQ-v2", "TACO"] and set(table["verdict"]) == {V.NOT_ENOUGH}
    for name in ("verify.md", "verify.tex", "verify_frames.csv", "verify.png", "verify.pdf"):
        assert (tmp_path / "out" / name).is_file()
    evals = sorted((tmp_path / "runs" / "verify").glob("*/base/cartpole_balance/seed_1/eval.csv"))
    assert len(evals) == 2 and all(len(pd.read_csv(e)) == 2 for e in evals)  # frames 0 and 200
    again = _verify(*args)
    assert again.returncode == 0 and "2 already done" in again.stdout
    # the kept copies (no checkpoint, no replay) are a results root that judges the same
    kept = tmp_path / "out" / "runs" / "verify" / "drqv2" / "base" / TASK / "seed_1"
    assert sorted(p.name for p in kept.iterdir()) == sorted(V.KEPT_FILES)
    rejudged = _verify("--judge-only", "-r", str(tmp_path / "out" / "runs"), "-o", str(tmp_path / "out2"))
    assert rejudged.returncode == 0, rejudged.stdout + rejudged.stderr
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "out2" / "verify.csv"), table)


@pytest.mark.parametrize("record, verdicts", [("bf16_heads", [V.BELOW]), ("", [V.LEARNS, V.LEARNED]),
                                             ("in_progress", [V.NOT_ENOUGH, V.NOT_ENOUGH])])
def test_the_kept_cpu_runs_are_judged_as_recorded(record, verdicts):
    """docs/verification/ holds the CPU check's run files and its verdicts, both written by `repro verify
    --judge-only --keep-runs`: judging the kept files again gives the recorded table (a change to the rule, the band
    or the kept files fails here). ``bf16_heads/``: the run with the actor and critic under bf16 autocast (issue 33's
    bug), below the band; the top folder: the same run after the fix, as published, and TACO's run beside it,
    learned; ``in_progress/``: issue 49's runs as far as they have come (TACO seed 2, fast at 20K frames and plain at
    its first checkpoint: short of the learned frame, 40K)."""
    kept = Path(__file__).resolve().parents[1] / "docs" / "verification" / record
    rows = V.judge(load_results(kept / "runs"))
    recorded = pd.read_csv(kept / "verify.csv")
    for col in ("note", "health", "environment"):  # an empty text (nothing to say) reads back as NaN
        recorded[col] = recorded[col].fillna("")
    pd.testing.assert_frame_equal(V.verdict_frame(rows).reset_index(drop=True), recorded, check_dtype=False)
    assert list(recorded["verdict"]) == verdicts


def test_verify_dry_run_prices_the_runs_from_a_bench_file(tmp_path):
    """`repro verify --dry-run` with a bench file: the CPU check's one DrQ-v2 run (60K frames, agent.fast) priced
    from the fast end-to-end entry (10 frames/s: 60000 / 10 / 3600 = 1.67 h), not the plain one (2 frames/s)."""
    import json

    from repro.bench.results import FORMAT

    bench = tmp_path / "runs" / "bench" / "bench-host-cpu.json"
    bench.parent.mkdir(parents=True)
    e2e = [{"agent": "drqv2", "batch_size": 256, "speedup": path, "phase_sync": True, "frames": 1000,
            "seconds": seconds} for path, seconds in (("plain", 500.0), ("fast", 100.0))]
    bench.write_text(json.dumps({"kind": "online", "format": FORMAT, "hardware": "Test cpu", "device": "cpu",
                                 "results": [], "e2e": e2e}))
    out = _verify("--dry-run", "--agents", "drqv2", "--seeds", "1", "-r", str(tmp_path / "runs"))
    assert out.returncode == 0, out.stdout + out.stderr
    assert "expected time on Test cpu" in out.stdout and "1.67 device-hours" in out.stdout, out.stdout
