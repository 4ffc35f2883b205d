"""F1 (fig:avg_performance): average return over the nine DMC tasks at 1M frames, with rliable aggregates."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from analysis import select
from analysis.comparable import env_label, paper_frames
from analysis.compare import cells_frame
from analysis.context import Context
from analysis.paper import DMC9
from analysis.stats import (
    POI_REPS,
    PROFILE_REPS,
    SCORE_SCALE,
    CellStats,
    aggregate_estimates,
    performance_profiles,
    probability_of_improvement,
    score_matrix,
)
from analysis.tables import Cell, fmt_ci, fmt_num, write_table
from paper_figures.common import (
    NO_RUNS_TEXT,
    banner,
    bar_caption,
    comparison_table,
    env_banner,
    grouped_bars,
    palette,
    placeholder,
    relabel,
    save_figure,
)
from paper_figures.registry import ArtifactResult, register

SCALE = SCORE_SCALE["episode_reward"]


def _online(ctx: Context) -> pd.DataFrame:
    """The runs of Table 1's cells (one row per run, scores at the budget), labelled by method."""
    return relabel(select.online_main(ctx.scores, ctx.experiment_map), "method")


def average_matrices(ctx: Context) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Per method with runs on all nine tasks: the (runs x 9) matrix of returns at the budget (reached runs)."""
    df = _online(ctx)
    df = df[df["reached"].astype(bool)] if not df.empty else df
    mats, notes = {}, {}
    for method in (df["method"].unique() if not df.empty else []):
        matrix, note = score_matrix(df[df["method"] == method], DMC9)
        notes[method] = note
        if matrix is not None:
            mats[method] = matrix
    return mats, notes


@register("F1", "Average return over nine DMC tasks", "figure", "fig:avg_performance")
def render(ctx: Context) -> ArtifactResult:
    paper = ctx.paper.online.groupby("method", sort=False)["mean"].mean()
    mats, mat_notes = average_matrices(ctx)
    normed = {m: x / SCALE for m, x in mats.items()}
    methods = list(paper.index) + [m for m in mats if m not in paper.index]
    cells, extra_rows = _cells(ctx, methods, paper, mats, mat_notes, normed)
    caption = (
        "Average episode return over the nine DMC tasks at the frame budget. Paper: the mean of Table 1's nine "
        "means (recomputed; the paper prints no number). Reproduced: rliable mean over runs and tasks with a "
        "95% stratified-bootstrap CI, shown only for methods with runs on all nine tasks; IQM and optimality "
        "gap (gamma=1, on returns / 1000) and the probability that TACO improves on the method (rliable; its CI "
        f"uses {min(ctx.reps, POI_REPS):,} repetitions)."
    )
    table = comparison_table(ctx, "F1", cells, caption, digits=0)
    for col in ("IQM", "Optimality gap", "P(TACO > method)"):
        table.display[col] = [r[col] for r in extra_rows]
    table = write_table(ctx.out_dir, "F1", pd.concat([table.data, pd.DataFrame(extra_rows)], axis=1),
                        caption, table.display, table.notes)
    png = _figure(ctx, cells, methods, normed)
    full_caption = (
        caption
        + " "
        + bar_caption(
            ctx, "Right: run-score performance profiles with 95% bootstrap bands (rliable, "
            f"{min(ctx.reps, PROFILE_REPS):,} repetitions)."
        )
    )
    return ArtifactResult("F1", "Average performance", full_caption, figures=[png], tables=[table], notes=table.notes,
                          has_runs=bool(mats))


def _cells(ctx: Context, methods: list[str], paper: pd.Series, mats: dict[str, np.ndarray], mat_notes: dict[str, str],
           normed: dict[str, np.ndarray]) -> tuple[list[Cell], list[dict[str, str]]]:
    """Per method: its comparison cell (paper value, rliable mean and CI) and its IQM / optimality gap /
    P(TACO > method) texts ("—" without runs on all nine tasks)."""
    agg = (
        aggregate_estimates(normed, reps=ctx.reps, seed=ctx.seed)
        if normed
        else pd.DataFrame(columns=["method", "metric"])
    )
    cells, extra_rows = [], []
    for method in methods:
        a = agg[agg["method"] == method]
        stats = CellStats(0, math.nan, math.nan, math.nan, math.nan)
        row = {"IQM": "—", "Optimality gap": "—", "P(TACO > method)": "—"}
        if not a.empty:
            stats = _aggregate_cell(a, mats[method], row)
            if "TACO" in mats and method != "TACO":
                p, lo, hi = probability_of_improvement(
                    normed["TACO"], normed[method], min(ctx.reps, POI_REPS), ctx.seed
                )
                row["P(TACO > method)"] = f"{p:.2f} {fmt_ci(lo, hi, 2)}"
        note = mat_notes.get(method, "no runs") if method not in mats else mat_notes[method]
        runs = _online(ctx)
        runs = runs[runs["method"] == method] if not runs.empty else runs
        budget = ctx.frames_budget(runs[runs["reached"].astype(bool)]) if method in mats else None
        note = "; ".join(n for n in (note, env_label(runs)) if n)
        cells.append(
            Cell({"method": method}, float(paper[method]) if method in paper.index else None, None, stats, note=note,
                 budget=budget, paper_budget=paper_frames())
        )
        extra_rows.append(row)
    return cells, extra_rows


def _aggregate_cell(a: pd.DataFrame, matrix: np.ndarray, row: dict[str, str]) -> CellStats:
    """A method's rliable Mean (with its CI) as the cell's statistics, on the return scale; fills ``row``'s
    IQM and optimality-gap texts."""
    mean_row = a[a["metric"] == "Mean"].iloc[0]
    n = matrix.shape[0]
    per_run = matrix.mean(axis=1)
    stats = CellStats(n, mean_row["value"] * SCALE, float(np.std(per_run, ddof=1)) if n > 1 else math.nan,
                      mean_row["ci_low"] * SCALE, mean_row["ci_high"] * SCALE)
    iqm = a[a["metric"] == "IQM"].iloc[0]
    og = a[a["metric"] == "Optimality Gap"].iloc[0]
    row["IQM"] = (
        f"{fmt_num(iqm['value'] * SCALE, 0)} {fmt_ci(iqm['ci_low'] * SCALE, iqm['ci_high'] * SCALE, 0)}"
    )
    row["Optimality gap"] = f"{og['value']:.3f} {fmt_ci(og['ci_low'], og['ci_high'], 3)}"
    return stats


def _figure(ctx: Context, cells: list[Cell], methods: list[str], normed: dict[str, np.ndarray]) -> Path:
    """Left: the average per method (bars); right: rliable performance profiles (or a placeholder)."""
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.3, 1]})
    cf = cells_frame(cells).assign(group="avg")
    grouped_bars(ax, cf, "method", "group", methods, ["avg"], x_labels=methods, colors={"avg": "#4c72b0"})
    ax.get_legend().remove()
    for i, method in enumerate(methods):
        ax.get_xticklabels()[i].set_color(palette(methods)[method])
    ax.set_ylabel(f"mean return over 9 tasks at {ctx.frames_budget(_online(ctx)).text()}")
    ax.set_title("Average over nine DMC tasks")
    ax.tick_params(axis="x", rotation=30)
    if normed:
        taus = np.linspace(0.0, 1.0, 51)
        profiles = performance_profiles(normed, taus, reps=min(ctx.reps, PROFILE_REPS), seed=ctx.seed)
        colors = palette(list(normed))
        for method, (prof, ci) in profiles.items():
            ax2.plot(taus * SCALE, prof, color=colors[method], label=method)
            ax2.fill_between(taus * SCALE, ci[0], ci[1], color=colors[method], alpha=0.2, lw=0)
        ax2.set_xlabel("return threshold τ")
        ax2.set_ylabel("fraction of runs with return > τ")
        ax2.set_title("Performance profile (rliable)")
        ax2.legend(fontsize=8)
    else:
        placeholder(ax2, "performance profile: needs runs of a method on all nine DMC tasks")
    if ctx.no_runs:
        banner(fig, NO_RUNS_TEXT)
    env_banner(fig, _online(ctx))
    return save_figure(fig, ctx, "F1")
