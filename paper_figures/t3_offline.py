"""T3 (tab:offline_table): offline normalised scores, 4 tasks x 3 datasets x 7 methods, + average row."""

from __future__ import annotations

import math

import numpy as np

from analysis import select
from analysis.compare import build_cells
from analysis.context import Context
from analysis.scores import best_online_returns, normalize_offline
from analysis.stats import CellStats, grand_mean_ci, score_matrix
from analysis.tables import Cell
from paper_figures.common import comparison_table, has_data, relabel
from paper_figures.registry import ArtifactResult, register


def _paper_cell(ctx: Context, key: dict) -> tuple[float, float] | None:
    p = ctx.paper.offline
    rows = p[(p["task"] == key["task"]) & (p["dataset"] == key["dataset"]) & (p["method"] == key["method"])]
    if rows.empty:
        return None
    return float(rows.iloc[0]["normalized_mean"]), float(rows.iloc[0]["normalized_std"])


def _average_cells(ctx: Context, df, cells: list[Cell]) -> list[Cell]:
    """One 'Average' cell per method: the mean over the 12 task/dataset pairs, only if all 12 have runs."""
    paper_avg = dict(zip(ctx.paper.offline_average["method"], ctx.paper.offline_average["average_normalized"]))
    recomputed = ctx.paper.offline.groupby("method")["normalized_mean"].mean()
    pairs = ctx.paper.offline[["task", "dataset"]].drop_duplicates()
    out = []
    for method in ctx.paper.offline_average["method"]:
        mine = [c for c in cells if c.keys["method"] == method]
        covered = sum(1 for c in mine if c.stats.n > 0)
        stats = CellStats(0, math.nan, math.nan, math.nan, math.nan)
        note = f"paper's cells average to {recomputed.get(method, math.nan):.1f}"
        if covered == len(pairs) and not df.empty:
            rows = df[(df["method"] == method) & df["reached"].astype(bool)]
            rows = rows.assign(task=rows["task"] + "/" + rows["dataset"])
            pair_ids = [f"{t}/{d}" for t, d in zip(pairs["task"], pairs["dataset"])]
            matrix, mnote = score_matrix(rows, pair_ids, value="normalized")
            if matrix is not None:
                mean, lo, hi = grand_mean_ci(matrix, ctx.reps, ctx.seed)
                stats = CellStats(
                    int(matrix.shape[0]),
                    mean,
                    float(np.std(matrix.mean(axis=1), ddof=1)) if matrix.shape[0] > 1 else math.nan,
                    lo,
                    hi,
                )
                note += f"; {mnote}; std over runs of the per-run average"
        elif covered:
            note += f"; only {covered}/{len(pairs)} pairs have runs: no average"
        out.append(Cell({"task": "Average", "dataset": "all 12", "method": method},
                        float(paper_avg[method]), None, stats, note=note))
    return out


@register("T3", "Offline RL: normalised scores", "table", "tab:offline_table")
def render(ctx: Context) -> ArtifactResult:
    normalizers = best_online_returns(ctx.results)
    df = relabel(select.offline(ctx.scores, ctx.experiment_map), "method")
    df = normalize_offline(df, normalizers) if not df.empty else df.assign(normalized=[])
    paper = ctx.paper.offline
    expected = [
        {"task": t, "dataset": d, "method": m} for t, d, m in zip(paper["task"], paper["dataset"], paper["method"])
    ]

    def note(key: dict, rows) -> str:
        if not rows.empty and key["task"] not in normalizers:
            return "no online TACO run on this task to normalise by"
        return ""

    cells = build_cells(df, ["task", "dataset", "method"], expected, paper=lambda k: _paper_cell(ctx, k),
                        value="normalized", reps=ctx.reps, seed=ctx.seed, note=note)
    cells += _average_cells(ctx, df, cells)
    caption = (
        "Offline normalised score: 100 x offline return at the budget / best evaluation return of online TACO "
        "on the task (max over all evaluations of the online TACO runs of experiment 'main', or of any "
        "experiment if main has none on the task; the paper normalises by the best online TACO return). "
        "Average row: mean over the 12 task/dataset pairs; the "
        "paper column is the average row as printed."
    )
    notes = []
    if normalizers:
        notes.append(
            "Normalisers (best online TACO return): "
            + ", ".join(f"{k} {v:.1f}" for k, v in sorted(normalizers.items()))
        )
    table = comparison_table(ctx, "T3", cells, caption, notes)
    return ArtifactResult("T3", "Offline RL", caption, tables=[table], notes=table.notes, has_runs=has_data(cells))
