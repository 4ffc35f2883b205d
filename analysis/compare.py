"""Turn selected per-run scores into comparison cells (paper value beside reproduced statistics)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from analysis.comparable import Budget, env_label, paper_frames, rows_budget, stopped_text
from analysis.stats import DEFAULT_REPS, DEFAULT_SEED, CellStats, mean_cis, mean_std
from analysis.tables import Cell

PaperLookup = Callable[[dict[str, Any]], "tuple[float | None, float | None] | None"]


def build_cells(
    df: pd.DataFrame,
    keys: Sequence[str],
    expected: Sequence[dict[str, Any]] = (),
    paper: PaperLookup | None = None,
    value: str = "score",
    reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
    note: Callable[[dict[str, Any], pd.DataFrame], str] | None = None,
    paper_budget: Budget | None = None,
    varied: Sequence[str] = (),
) -> list[Cell]:
    """One :class:`Cell` per key combination: every ``expected`` one (empty if no runs), then extra ones.

    Statistics use the runs that reached the frame budget (``reached``); the others are counted in
    ``n_short`` (where they stopped: ``short_at``). ``paper`` maps a key dict to the paper's (mean, std) or None,
    given at ``paper_budget`` (default: the paper's 1M environment frames); each cell's ``budget`` is its runs'
    (analysis.comparable.rows_budget), so the table shows a Δ only where analysis.comparable's rule allows. A cell
    whose runs' environment differs from the paper's says how in its note (leaving out the dimensions ``varied``,
    the artifact's own variable).
    """
    paper_budget = paper_frames() if paper_budget is None else paper_budget
    keys = list(keys)
    groups: dict[tuple, pd.DataFrame] = {}
    if not df.empty:
        for k, rows in df.groupby(keys, sort=True, dropna=False):
            groups[k if isinstance(k, tuple) else (k,)] = rows
    order = [tuple(e[k] for k in keys) for e in expected]
    order += [k for k in groups if k not in order]
    columns, shorts, frames, reached = [], [], [], []
    for k in order:
        rows = groups.get(k, pd.DataFrame(columns=[value, "reached"]))
        ok = rows[rows["reached"].astype(bool)] if not rows.empty else rows
        columns.append(pd.to_numeric(ok[value], errors="coerce").to_numpy(dtype=float))
        shorts.append(int(len(rows) - len(ok)))
        frames.append(rows)
        reached.append(ok)
    cis = mean_cis(columns, reps=reps, seed=seed)
    cells = []
    for k, col, n_short, rows, ok, (lo, hi) in zip(order, columns, shorts, frames, reached, cis):
        key = dict(zip(keys, k))
        n, mean, std = mean_std(col)
        ref = paper(key) if paper else None
        pm, ps = (ref if ref is not None else (None, None))
        notes = [note(key, rows)] if note else []
        notes.append(env_label(rows, varied))
        if not rows.empty and {"experiment", "variant"} <= set(rows.columns):
            sources = sorted(set(zip(rows["experiment"], rows["variant"])))
            if len(sources) > 1:
                notes.append("runs from " + ", ".join(f"{e}/{v}" for e, v in sources))
        cells.append(
            Cell(
                keys=key,
                paper_mean=pm,
                paper_std=ps,
                stats=CellStats(n, mean, std, lo, hi),
                n_short=n_short,
                note="; ".join(n for n in notes if n),
                budget=rows_budget(ok[ok[value].notna()]) if not ok.empty else None,
                paper_budget=paper_budget,
                short_at=stopped_text(rows[~rows["reached"].astype(bool)]) if n_short else "",
            )
        )
    return cells


def cells_frame(cells: Sequence[Cell]) -> pd.DataFrame:
    """A plain frame of cells for plotting: keys, paper, n, n_short, mean, std, ci_low, ci_high, comparable (with the
    paper's value, or no paper value), budget (its short text) and short_at."""
    rows = []
    for c in cells:
        rows.append(
            {
                **c.keys,
                "paper": np.nan if c.paper_mean is None else c.paper_mean,
                "n": c.stats.n,
                "n_short": c.n_short,
                "mean": c.stats.mean,
                "std": c.stats.std,
                "ci_low": c.stats.ci_low,
                "ci_high": c.stats.ci_high,
                # drawn beside the paper's value as comparable (analysis.comparable), else marked with its budget
                "comparable": c.comparable or c.paper_mean is None,
                "budget": "" if c.budget is None else c.budget.short(),
                "short_at": c.short_at,
            }
        )
    return pd.DataFrame(rows)
