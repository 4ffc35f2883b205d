"""Per-run scores at a frame budget (offline runs: at their own budget), learning curves on a common grid.

The metric is the DMC episode return (``episode_reward``) and, for Meta-world, the success rate in
percent (``success`` x 100), as the paper's Meta-world figure shows success rates. An offline run's
normalised score is the one it recorded (eval.csv ``normalized_score``: 100 x return / the reference return
named in ``score_reference``), never recomputed here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from analysis.load import IDENTITY, Results

DEFAULT_BUDGET = 1_000_000


def metric_of(suite: str | None) -> str:
    """The score column for a suite: ``success`` (percent) for Meta-world, else ``episode_reward``."""
    return "success" if suite == "metaworld" else "episode_reward"


def _values(rows: pd.DataFrame, metric: str) -> pd.Series:
    values = pd.to_numeric(rows[metric], errors="coerce")
    return values * 100.0 if metric == "success" else values


def final_scores(results: Results, budget: int = DEFAULT_BUDGET) -> pd.DataFrame:
    """One row per run: identity columns + ``score`` at the budget.

    Online runs: ``score`` is the evaluation at the largest frame <= ``budget``; ``frame`` is that frame.
    ``reached`` is true if the run has an evaluation at or past the budget, or is done with
    ``train.frames >= budget``; runs that did not reach it keep their score (at an earlier frame) but
    are flagged, and the tables count them separately.

    Offline runs (a dataset) are scored at their own budget, whatever ``budget`` says: the evaluation at the
    largest update <= the run's ``offline.updates`` (``update``), its return as ``score`` and the normalised
    score the run recorded (``normalized``, eval.csv's ``normalized_score``, with its ``score_reference``);
    ``reached`` when the run is done and evaluated at its ``offline.updates``. Online rows have no
    ``normalized``; offline rows no ``frame``.
    """
    cols = [*IDENTITY, "metric", "score", "frame", "reached", "last_frame", "normalized", "score_reference",
            "update", "last_update"]
    if results.runs.empty:
        return pd.DataFrame(columns=cols)
    out = []
    grouped = dict(tuple(results.eval.groupby("run_id"))) if not results.eval.empty else {}
    for run in results.runs.itertuples(index=False):
        row = {k: getattr(run, k) for k in IDENTITY}
        rows = grouped.get(run.run_id)
        if not pd.isna(run.dataset):
            row.update(_offline_score(run, rows))
            out.append(row)
            continue
        metric = metric_of(run.suite)
        score, frame, last = math.nan, math.nan, math.nan
        if rows is not None and not rows.empty:
            last = float(rows["frame"].max())
            within = _at_budget(rows, "frame", budget)
            if not within.empty:
                pick = within.loc[within["frame"].idxmax()]
                frame = float(pick["frame"])
                value = pd.to_numeric(pd.Series([pick[metric]]), errors="coerce").iloc[0]
                score = float(value) * (100.0 if metric == "success" else 1.0)
        train_frames = run.train_frames if run.train_frames is not None else -1
        reached = (not math.isnan(last) and last >= budget) or (
            run.status == "done" and not pd.isna(train_frames) and train_frames >= budget
        )
        row.update(metric=metric, score=score, frame=frame, reached=bool(reached), last_frame=last,
                   normalized=math.nan, score_reference=None, update=math.nan, last_update=math.nan)
        out.append(row)
    return pd.DataFrame(out, columns=cols)


def _offline_score(run: Any, rows: pd.DataFrame | None) -> dict[str, Any]:
    """The score columns of one offline run at its own budget (see :func:`final_scores`)."""
    out: dict[str, Any] = {"metric": "episode_reward", "score": math.nan, "frame": math.nan, "reached": False,
                           "last_frame": math.nan, "normalized": math.nan, "score_reference": None,
                           "update": math.nan, "last_update": math.nan}
    if rows is None or rows.empty:
        return out
    budget = run.offline_updates
    last = float(rows["update"].max())
    within = rows if pd.isna(budget) else _at_budget(rows, "update", budget)
    out["last_update"] = last
    if within.empty:
        return out
    pick = within.loc[within["update"].idxmax()]
    reference = pick["score_reference"]
    out.update(score=float(pick["episode_reward"]), update=float(pick["update"]),
               normalized=float(pd.to_numeric(pd.Series([pick["normalized_score"]]), errors="coerce").iloc[0]),
               score_reference=None if pd.isna(reference) else str(reference),
               reached=bool(run.status == "done" and not pd.isna(budget) and last >= budget))
    return out


def _budget_end(rows: pd.DataFrame) -> pd.Series:
    """Which of ``rows`` only a shorter budget's end produced (analysis.load.budget_end_rows; none without the
    column)."""
    if "budget_end" not in rows.columns:
        return pd.Series(False, index=rows.index)
    return rows["budget_end"].fillna(False).astype(bool)


def on_grid(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` without those only a shorter budget's end produced: the rows of a run trained to its budget in one
    go."""
    return rows[~_budget_end(rows)]


def _at_budget(rows: pd.DataFrame, x: str, budget: float) -> pd.DataFrame:
    """The rows a run has up to ``budget`` (its prefix): the grid rows and a budget's-end row exactly at it, so a
    run extended past a budget scores there as the same run stopped at it."""
    within = rows[rows[x] <= budget]
    return within[~_budget_end(within) | (within[x] == budget)]


def common_grid(eval_df: pd.DataFrame, step: int | None = None, max_frame: float | None = None) -> np.ndarray:
    """A frame grid from 0 to the largest evaluated frame (or ``max_frame``).

    ``step`` defaults to the median spacing of evaluations (10k frames in the paper's setup).
    """
    if eval_df.empty:
        return np.array([0.0])
    if step is None:
        diffs = eval_df.sort_values(["run_id", "frame"]).groupby("run_id")["frame"].diff().dropna()
        diffs = diffs[diffs > 0]
        step = int(diffs.median()) if len(diffs) else 1
    top = float(eval_df["frame"].max()) if max_frame is None else float(max_frame)
    return np.arange(0.0, top + 0.5 * step, step)


def learning_curves(results: Results, grid: np.ndarray | None = None, step: int | None = None) -> pd.DataFrame:
    """Long table of every run's curve on a common frame grid.

    Each run is linearly interpolated between its evaluations; grid points beyond a run's last
    evaluation are left out (no extrapolation), so later points average over fewer seeds, and the
    number of seeds per point is kept by the callers. Offline runs (evaluated at updates, not frames) have
    no curve here.
    """
    cols = [*IDENTITY, "frame", "value"]
    online = on_grid(results.eval[results.eval["frame"].notna()]) if not results.eval.empty else results.eval
    if online.empty:
        return pd.DataFrame(columns=cols)
    if grid is None:
        grid = common_grid(online, step=step)
    parts = []
    for _, rows in online.groupby("run_id", sort=False):
        rows = rows.sort_values("frame")
        metric = metric_of(rows["suite"].iloc[0])
        vals = _values(rows, metric).to_numpy(dtype=float)
        frames = rows["frame"].to_numpy(dtype=float)
        ok = ~np.isnan(vals)
        if not ok.any():
            continue
        frames, vals = frames[ok], vals[ok]
        g = grid[(grid >= frames[0]) & (grid <= frames[-1])]
        part = pd.DataFrame({"frame": g, "value": np.interp(g, frames, vals)})
        for key in IDENTITY:
            part[key] = rows[key].iloc[0]
        parts.append(part)
    if not parts:
        return pd.DataFrame(columns=cols)
    return pd.concat(parts, ignore_index=True)[cols]
