"""Every artifact renders on a synthetic full-coverage results root and on an empty one; F6 helpers."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
import torch
import typer
from typer.testing import CliRunner

import paper_figures
import repro_app.report
from analysis.claims import NO_DATA, SUPPORTED
from analysis.context import Context
from analysis.load import load_results
from analysis.tsne import build_step_mlp, find_action_encoder_state, run_tsne
from analysis_fixtures import FRAMES, full_coverage_root
from repro_app.analysis_cli import register
from repro_app.report import build_report

# its module-scoped runs are made once: every test of this module on one pytest-xdist worker
pytestmark = pytest.mark.xdist_group("figures")

REPS = 200
CURVE_REPS = 50  # repetitions of the learning curves' CI bands (default 2,000): no test here reads a band's width
EXPECTED = ["T1", "T2", "T3", "T3b", "T4", "T5", "T6", "F1", "F3", "F4", "F5", "F6", "F7a", "F7b", "F8", "F9", "F10",
            "F11", "F12", "F13"]


def assert_png_not_blank(path: Path) -> None:
    assert path.exists() and path.stat().st_size > 2000, path
    img = mpimg.imread(path)[..., :3]
    assert img.shape[0] > 100 and img.shape[1] > 100
    assert float(img.var()) > 1e-3, f"{path} looks blank"
    assert path.with_suffix(".pdf").stat().st_size > 1000


@pytest.fixture(scope="module")
def full_report(tmp_path_factory):
    root = full_coverage_root(tmp_path_factory.mktemp("results"))
    ctx = Context(results=load_results(root), out_dir=tmp_path_factory.mktemp("report"), budget=FRAMES, reps=REPS,
                  curve_reps=CURVE_REPS, tsne_n=30, tsne_iter=250, render_envs=False, indicative=True)
    with pytest.MonkeyPatch.context() as mp:
        # the power section's draws (default 500, ~14 s here): its numbers are tests/test_plan.py's, not read here
        mp.setattr(repro_app.report, "REPORT_SIMS", 20)
        md, html = build_report(ctx)
    return ctx, md, html


def test_registry_has_every_artifact():
    assert paper_figures.sorted_ids() == EXPECTED
    assert [a.id for a in paper_figures.resolve(["f7", "T1"])] == ["F7a", "F7b", "T1"]
    with pytest.raises(paper_figures.UnknownArtifactError):
        paper_figures.resolve(["F2"])


# The full-coverage report (about 60 s of CPU for ~390 synthetic runs and every artifact) is an end-to-end check:
# `make test` runs it, `make test-fast` (unit tests) does not.
@pytest.mark.slow
def test_every_figure_renders_non_blank_on_full_coverage(full_report):
    ctx, _, _ = full_report
    manifest = {m["id"]: m for m in json.loads((ctx.out_dir / "manifest.json").read_text())}
    assert list(manifest) == EXPECTED
    for aid, entry in manifest.items():
        for png in entry["figures"]:
            assert_png_not_blank(ctx.out_dir / png)
        for suffix in ("csv", "md", "tex"):
            if aid.startswith("T"):
                assert (ctx.out_dir / f"{aid}.{suffix}").stat().st_size > 100
        if aid not in ("F13",):
            assert entry["has_runs"], f"{aid} found no runs in the full-coverage root"


@pytest.mark.slow
def test_full_coverage_tables_and_claims(full_report):
    ctx, md, html = full_report
    import pandas as pd

    t2 = pd.read_csv(ctx.out_dir / "T2.csv").set_index(["task", "method"])
    assert t2.loc[("hopper_hop", "SPR"), "repro_mean"] == pytest.approx(245.0)  # 300 * 0.5 + 100 - 5 (2 seeds)
    assert t2.loc[("hopper_hop", "TACO"), "n"] == 2
    f9 = pd.read_csv(ctx.out_dir / "F9.csv").set_index(["ar", "k"])
    assert f9.loc[(1, "K=5"), "repro_mean"] == pytest.approx(395.0)
    f6 = pd.read_csv(ctx.out_dir / "F6.csv").set_index("space")
    assert f6.loc["latent", "silhouette_tsne_2d"] > 0.5 > f6.loc["raw", "silhouette_tsne_2d"]
    claims = pd.read_csv(ctx.out_dir / "claims.csv", keep_default_na=False).set_index("id")
    # the synthetic runs stop at 100k frames with 2 seeds: below every claim's budget, so no verdict, but
    # the indicative readings (asked for) show what the checks find
    assert set(claims.drop(index="speed")["verdict"]) == {NO_DATA}
    holds = {"online_beats_drqv2_all": "TACO ahead on every task", "horizon_choice": "K choice as stated",
             "action_repeat": "best K as stated", "batch_size": "TACO grows with batch and DrQ-v2 flat",
             "objective_removal": "removing TACO hurts most", "action_dim": "robust except at 6 and 24",
             "metaworld": "TACO ahead on every task", "vs_repr_objectives": "TACO ahead of every objective",
             "offline_gain": "TACO adds on every pair", "offline_average": "averages off the paper"}
    for cid, words in holds.items():
        assert claims.loc[cid, "indicative"].startswith(f"indicative: {words} ("), (cid, claims.loc[cid, "evidence"])
    assert claims.loc["online_beats_drqv2_all", "indicative"].endswith("(100,000 frames, 2 seeds)")
    assert claims.loc["speed", "verdict"] == SUPPORTED  # a timing: no training budget, one measurement a setting
    assert claims.loc["tsne_clusters", "indicative"].startswith("indicative: latent actions cluster")
    text = md.read_text()
    for aid in EXPECTED:
        assert f"## {aid}:" in text
    for section in ("## Claims", "## Audit", "## Provenance", "abc1234"):
        assert section in text
    page = html.read_text()
    assert "<table>" in page and 'src="F1.png"' not in page  # REPORT.html embeds its figures (one file)
    assert '<img src="data:image/png;base64,' in page and 'alt="F1"' in page


@pytest.mark.slow
def test_full_coverage_report_cannot_be_misread(full_report):
    """Issue 52's rules on the full-coverage tree (every artifact; its runs stop at 100K frames, the paper's values
    are at 1M): no reproduced value stands beside the paper's with a Δ or 'Paper in CI' (each says its budget and
    'not comparable'), every budget says env. frames with the action repeat beside them, F4 draws no diamond beside
    the short curves and says so, the claims summary counts the table's rows."""
    import pandas as pd

    ctx, md, _ = full_report
    t1 = pd.read_csv(ctx.out_dir / "T1.csv")
    shown = t1[t1["n"] > 0]
    assert len(shown) >= 27 and not shown["comparable"].any() and shown["diff"].isna().all()
    t1_md = (ctx.out_dir / "T1.md").read_text()
    assert "| Paper (1M env. frames, action repeat 2) | Reproduced (100K env. frames, action repeat 2) |" in t1_md
    rows = [ln for ln in t1_md.splitlines() if ln.startswith("| ") and "(100K frames, not comparable)" in ln]
    assert len(rows) == len(shown) and all("| n/a | n/a |" in ln for ln in rows)  # no Δ, no Paper in CI
    claims = pd.read_csv(ctx.out_dir / "claims.csv", keep_default_na=False).set_index("id")
    frames = claims[claims["budget"].str.contains("frames")]["budget"]
    assert len(frames) >= 15 and frames.str.contains(r"env\. frames \(action repeat").all()
    assert claims.loc["action_repeat", "budget"] == "1M env. frames (action repeat 1, 2, 4)"
    assert claims.loc["offline_gain", "budget"] == "each run's offline.updates (gradient updates)"
    text = md.read_text()
    assert "; scores at 100K env. frames (action repeat 1, 2, 4);" in text  # the header's budget, its unit, repeats
    assert "the runs of Quadruped Run, Hopper Hop, Walker Run" in text and "stop short" in text  # F4's caption
    counted = next(ln for ln in text.splitlines() if " rows (the paper's " in ln)
    assert f"{len(claims)} rows" in counted


def test_paper_only_view_with_no_runs(tmp_path):
    app = typer.Typer()
    register(app)
    (tmp_path / "empty").mkdir()
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["figures", "--all", "--results", str(tmp_path / "empty"), "--out", str(out),
                                      "--reps", "50", "--tsne-n", "20", "--no-render-envs"])
    assert result.exit_code == 0, result.output
    assert "No runs found" in result.output
    for aid in EXPECTED:
        if aid.startswith("F"):
            assert_png_not_blank(out / f"{aid}.png")
    t1 = (out / "T1.md").read_text()
    assert "No runs were found" in t1 and "| Quadruped Run | TACO | 541 ± 38 | no runs | 0 |" in t1


# ---------------------------------------------------------------- F6 helpers
def _encoder_state(true_dim=6, distract=20, latent=8):
    g = torch.Generator().manual_seed(1)
    w0 = torch.randn(64, true_dim + distract, generator=g)
    w0[:, true_dim:] = 0.0
    return {"step.0.weight": w0, "step.0.bias": torch.randn(64, generator=g),
            "step.2.weight": torch.randn(latent, 64, generator=g), "step.2.bias": torch.randn(latent, generator=g)}


@pytest.mark.parametrize("layout", ["nested", "dotted", "flat"])
def test_action_encoder_found_in_checkpoint_layouts(layout):
    sd = _encoder_state()
    ckpt = {
        "nested": {"agent": {"action_encoder": {**sd, "seq.weight": torch.zeros(1)}, "critic": {}}},
        "dotted": {"agent": {"agent.action_encoder": sd}},
        "flat": {"agent": {f"action_encoder.{k}": v for k, v in sd.items()}},
    }[layout]
    state = find_action_encoder_state(ckpt)
    mlp = build_step_mlp(state)
    x = torch.randn(5, 26)
    expected = torch.tanh(x @ sd["step.0.weight"].T + sd["step.0.bias"]) @ sd["step.2.weight"].T + sd["step.2.bias"]
    assert torch.allclose(mlp(x), expected, atol=1e-6)


def test_tsne_scores_latent_clusters_above_raw():
    mlp = build_step_mlp(find_action_encoder_state({"agent": {"action_encoder": _encoder_state()}}))
    res = run_tsne(6, 20, mlp, n=30, seed=0, max_iter=250)
    assert res.raw_2d.shape == (120, 2) and res.latent_2d.shape == (120, 2)
    assert res.silhouette_latent > 0.9 and res.silhouette_raw < 0.2
    assert res.silhouette_latent_2d > res.silhouette_raw_2d
    assert np.bincount(res.labels).tolist() == [30, 30, 30, 30]


@pytest.mark.slow
def test_f1_performance_profiles_use_the_repetitions_asked_for(full_report):
    """--reps governs F1's profile bands too (capped at rliable's 2,000), and the caption says the number used."""
    _, md, _ = full_report
    assert f"performance profiles with 95% bootstrap bands (rliable, {REPS:,} repetitions)" in md.read_text()


def test_f8_reads_each_tasks_default_k_from_its_composition():
    """F8's diamond goes on the bar of the K each task's config sets (Appendix B: 1 on quadruped_run and walker_run,
    3 elsewhere): read from the kept composition, the same as a fresh compose; no K for a task without a file."""
    from analysis.paper import DMC9
    from paper_figures.f8_horizon import default_k
    from repro.config.compose import compose

    ks = {task: default_k(task) for task in DMC9}
    assert ks == {task: int(compose([f"task={task}"]).agent.K) for task in DMC9}
    assert ks == {task: 1 if task in ("quadruped_run", "walker_run") else 3 for task in DMC9}
    assert default_k("no_such_task") is None


def test_bars_and_curves_mark_short_runs_and_runs_of_another_environment(tmp_path, monkeypatch):
    """400-frame runs of 100-frame episodes beside the paper's 1M values: F8's bars are hatched, labelled with
    their budget and not comparable (no Δ); the figures name the episode length (banner, curve legends) and the
    frame axis its unit and action repeat. F4 draws no paper diamond beside the 400-frame curves (the runs did not
    reach the paper's 1M frames: analysis.comparable's rule), says so in the panel and its caption, and its axis ends
    at the data."""
    import matplotlib.pyplot as plt

    import paper_figures.bars
    import paper_figures.curves
    from analysis_fixtures import write_run

    for s in (1, 2):
        for agent, final in (("taco", 1.0), ("drqv2", 2.0)):
            write_run(tmp_path / "runs", experiment="tiny", agent=agent, task="cheetah_run", seed=s, final=final + s,
                      frames=400, eval_every=200, config={"env.max_episode_frames": 100})
    drawn: dict[str, object] = {}

    def keep(fig, ctx, name):  # what the figure holds, not written (writing is most of the time)
        drawn[name] = ([t.get_text() for t in fig.texts],
                       [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()],
                       [ax.get_xlabel() for ax in fig.axes], [ax.get_ylabel() for ax in fig.axes],
                       [p.get_hatch() for ax in fig.axes for p in ax.patches],
                       {ax.get_title(): ([t.get_text() for t in ax.texts], ax.get_xlim()[1],
                                         [ln.get_xdata()[0] for ln in ax.lines if ln.get_marker() == "D"])
                        for ax in fig.axes})
        plt.close(fig)
        return ctx.out_dir / f"{name}.png"

    for module in (paper_figures.bars, paper_figures.curves):
        monkeypatch.setattr(module, "save_figure", keep)
    ctx = Context(results=load_results(tmp_path / "runs"), out_dir=tmp_path / "out", budget=400, reps=REPS,
                  curve_reps=CURVE_REPS, experiment_map={"main": ["tiny"]}, published_band=False)
    results = {art.id: art.render(ctx) for art in paper_figures.resolve(["F8", "F4"])}
    texts, legend, _, ylabels, hatches, _ = drawn["F8"]
    assert any("environment differs from the paper's: 100-frame episodes (paper: 1,000)" in t for t in texts)
    assert "at 400 frames: not comparable with the paper" in legend and hatches.count("////") >= 2
    assert ylabels == ["return at 400 env. frames (action repeat 2)"]
    f8 = (ctx.out_dir / "F8.md").read_text()
    assert "| Cheetah Run | K=3 | 821 ± 48 | 2 ± 1 (400 frames, not comparable) | 2 | [2, 3] | n/a | n/a |" in f8
    _, legend, xlabels, _, _, panels = drawn["F4"]
    assert "TACO (n=2; 100-frame episodes (paper: 1,000))" in legend
    assert set(xlabels) == {"environment frames (action repeat 2)"}
    notes, right, diamonds = panels["Cheetah Run"]
    assert notes == ["runs at 400 frames: the paper's\n1M frames values not comparable"] and diamonds == []
    assert right < 1000  # the axis ends at the data, not at the paper's 1M
    assert all(d == [1e6] * 3 for title, (_, _, d) in panels.items() if title != "Cheetah Run")  # no runs: paper's
    assert "the runs of Cheetah Run stop short, their values are not comparable" in results["F4"].caption
