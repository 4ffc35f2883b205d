"""Offline results (Table 3 and its ±TACO comparison) from offline runs, each at its own budget.

Every number comes from the runs: the normalised score each run recorded in its eval.csv at its own
``offline.updates`` (analysis.scores.final_scores), the dataset and CQL alpha of its resolved.json. A cell
uses only runs that finished their budget (``reached``: DONE and evaluated at ``offline.updates``); the
others are counted as short.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from analysis import select
from analysis.comparable import paper_updates, rows_budget
from analysis.compare import build_cells
from analysis.paper import PaperData
from analysis.stats import CellStats, grand_mean_ci, poi_interval, score_matrix
from analysis.tables import Cell

# (method with TACO, its base method): the paper's paired comparison of Table 3.
TACO_PAIRS = (("TD3+BC+TACO", "TD3+BC"), ("CQL+TACO", "CQL"))
POI_MAX_REPS = 5_000  # bootstrap repetitions of a probability of improvement, at most (about 0.3 ms each)
ALL_PAIRS = "all 12"  # the dataset column of the rows over every task/dataset pair
POI_COLUMNS = ["task", "dataset", "method", "baseline", "n_method", "n_baseline", "mean_method", "mean_baseline",
               "poi", "ci_low", "ci_high", "note"]


def offline_runs(scores: pd.DataFrame, experiment_map: select.ExperimentMap | None = None) -> pd.DataFrame:
    """Per-run rows of the offline experiment with the paper's method name in ``method`` (``CQL+TACO``...)."""
    df = select.offline(scores, experiment_map)
    if "label" not in df.columns:
        return df.assign(method=pd.Series(dtype=object))
    return df.drop(columns=["method"], errors="ignore").rename(columns={"label": "method"})


def _paper_cell(paper: PaperData, key: dict) -> tuple[float, float] | None:
    p = paper.offline
    rows = p[(p["task"] == key["task"]) & (p["dataset"] == key["dataset"]) & (p["method"] == key["method"])]
    if rows.empty:
        return None
    return float(rows.iloc[0]["normalized_mean"]), float(rows.iloc[0]["normalized_std"])


def _reference_note(key: dict, rows: pd.DataFrame) -> str:
    """What a cell's reader must know about its runs' normalisation."""
    if rows.empty:
        return ""
    notes = []
    refs = sorted({str(r) for r in rows["score_reference"].dropna()})
    if len(refs) > 1:
        notes.append("runs normalised by different references: " + ", ".join(refs))
    if rows["normalized"].isna().any() and rows["score"].notna().any():
        notes.append("some runs recorded no normalised score (no reference return)")
    return "; ".join(notes)


def t3_cells(df: pd.DataFrame, paper: PaperData, reps: int, seed: int) -> list[Cell]:
    """Table 3's cells (task x dataset x method, the paper's order) and its average row, from ``df``
    (:func:`offline_runs`); the value is each run's recorded normalised score."""
    expected = [{"task": t, "dataset": d, "method": m}
                for t, d, m in zip(paper.offline["task"], paper.offline["dataset"], paper.offline["method"])]
    if df.empty:
        df = df.assign(normalized=pd.Series(dtype=float), score_reference=pd.Series(dtype=object))
    cells = build_cells(df, ["task", "dataset", "method"], expected, paper=lambda k: _paper_cell(paper, k),
                        value="normalized", reps=reps, seed=seed, note=_reference_note, paper_budget=paper_updates())
    return cells + average_cells(df, cells, paper, reps, seed)


def average_cells(df: pd.DataFrame, cells: Sequence[Cell], paper: PaperData, reps: int, seed: int) -> list[Cell]:
    """One 'Average' cell per method of the paper's average row: the mean over the 12 task/dataset pairs of
    the runs' normalised scores (rliable's stratified bootstrap over a runs x pairs matrix), only when every
    pair has finished runs; the paper's printed average beside it."""
    printed = dict(zip(paper.offline_average["method"], paper.offline_average["average_normalized"]))
    recomputed = paper.offline.groupby("method")["normalized_mean"].mean()
    pairs = paper.offline[["task", "dataset"]].drop_duplicates()
    pair_ids = [f"{t}/{d}" for t, d in zip(pairs["task"], pairs["dataset"])]
    out = []
    for method in paper.offline_average["method"]:
        covered = sum(1 for c in cells if c.keys["method"] == method and c.keys["task"] != "Average" and c.stats.n)
        stats = CellStats(0, math.nan, math.nan, math.nan, math.nan)
        budget = None
        note = f"the paper's cells average to {recomputed.get(method, math.nan):.1f}"
        if covered == len(pair_ids) and not df.empty:
            matrix, mnote = pair_matrix(df, method, pair_ids)
            if matrix is not None:
                mean, lo, hi = grand_mean_ci(matrix, reps, seed)
                per_run = matrix.mean(axis=1)
                std = float(np.std(per_run, ddof=1)) if len(per_run) > 1 else math.nan
                stats = CellStats(int(matrix.shape[0]), mean, std, lo, hi)
                budget = rows_budget(df[(df["method"] == method) & df["reached"].astype(bool)])
                note += f"; {mnote}; std over runs of the per-run average"
        elif covered:
            note += f"; only {covered}/{len(pair_ids)} pairs have finished runs: no average"
        out.append(Cell({"task": "Average", "dataset": ALL_PAIRS, "method": method}, float(printed[method]), None,
                        stats, note=note, budget=budget, paper_budget=paper_updates()))
    return out


def pair_matrix(df: pd.DataFrame, method: str, pair_ids: Sequence[str], value: str = "normalized"
                ) -> tuple[np.ndarray | None, str]:
    """(runs x task/dataset pairs) matrix of ``method``'s finished runs (analysis.stats.score_matrix)."""
    rows = df[(df["method"] == method) & df["reached"].astype(bool)]
    rows = rows.assign(task=rows["task"] + "/" + rows["dataset"])
    return score_matrix(rows, list(pair_ids), value=value)


def taco_poi(df: pd.DataFrame, paper: PaperData, reps: int, seed: int) -> pd.DataFrame:
    """Paired ±TACO comparison: per task, dataset and pair (TD3+BC+TACO vs TD3+BC, CQL+TACO vs CQL),
    rliable's probability of improvement P(+TACO > base) over the finished runs' normalised scores with its
    95% stratified-bootstrap CI (analysis.stats.poi_interval), then the same over all 12 pairs (rliable's
    multi-task form). A comparison needs >= 2 finished runs on each side; repetitions are capped at
    :data:`POI_MAX_REPS`."""
    reps = min(reps, POI_MAX_REPS)
    pairs = paper.offline[["task", "dataset"]].drop_duplicates()
    pair_ids = [f"{t}/{d}" for t, d in zip(pairs["task"], pairs["dataset"])]
    ok = df[df["reached"].astype(bool) & df["normalized"].notna()] if not df.empty else df
    rows = []
    for method, base in TACO_PAIRS:
        for task, dataset in zip(pairs["task"], pairs["dataset"]):
            cell = ok[(ok["task"] == task) & (ok["dataset"] == dataset)] if not ok.empty else ok
            x = _column(cell, method)
            y = _column(cell, base)
            rows.append(_poi_row(task, dataset, method, base, x[:, None], y[:, None], reps, seed))
        xm, _ = pair_matrix(ok, method, pair_ids) if not ok.empty else (None, "")
        ym, _ = pair_matrix(ok, base, pair_ids) if not ok.empty else (None, "")
        if xm is None or ym is None:
            empty = np.zeros((0, 1))
            row = _poi_row("All", ALL_PAIRS, method, base, empty, empty, reps, seed)
            row["note"] = "needs finished runs on every task/dataset pair"
            rows.append(row)
        else:
            rows.append(_poi_row("All", ALL_PAIRS, method, base, xm, ym, reps, seed))
    return pd.DataFrame(rows, columns=POI_COLUMNS)


def _column(rows: pd.DataFrame, method: str) -> np.ndarray:
    if rows.empty:
        return np.zeros(0)
    return rows[rows["method"] == method].sort_values("seed")["normalized"].to_numpy(dtype=float)


def _poi_row(task: str, dataset: str, method: str, base: str, x: np.ndarray, y: np.ndarray, reps: int,
             seed: int) -> dict:
    n_x, n_y = int(x.shape[0]), int(y.shape[0])
    poi = lo = hi = math.nan
    note = ""
    if min(n_x, n_y) >= 2:
        poi, lo, hi = poi_interval(x, y, reps=reps, seed=seed)
    elif n_x or n_y:
        note = "needs >= 2 finished runs of each method"
    return {"task": task, "dataset": dataset, "method": method, "baseline": base, "n_method": n_x,
            "n_baseline": n_y, "mean_method": float(x.mean()) if n_x else math.nan,
            "mean_baseline": float(y.mean()) if n_y else math.nan, "poi": poi, "ci_low": lo, "ci_high": hi,
            "note": note}
