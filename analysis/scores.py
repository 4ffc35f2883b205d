"""Per-run scores at a frame budget, learning curves on a common grid, offline normalisation.

The metric is the DMC episode return (``episode_reward``) and, for Meta-world, the success rate in
percent (``success`` x 100), as the paper's Meta-world figure shows success rates.
"""

from __future__ import annotations

import math

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

    ``score`` is the evaluation at the largest frame <= ``budget``; ``frame`` is that frame.
    ``reached`` is true if the run has an evaluation at or past the budget, or is done with
    ``train.frames >= budget``; runs that did not reach it keep their score (at an earlier frame) but
    are flagged, and the tables count them separately.
    """
    cols = [*IDENTITY, "metric", "score", "frame", "reached", "last_frame"]
    if results.runs.empty:
        return pd.DataFrame(columns=cols)
    out = []
    grouped = dict(tuple(results.eval.groupby("run_id"))) if not results.eval.empty else {}
    for run in results.runs.itertuples(index=False):
        row = {k: getattr(run, k) for k in IDENTITY}
        metric = metric_of(run.suite)
        rows = grouped.get(run.run_id)
        score, frame, last = math.nan, math.nan, math.nan
        if rows is not None and not rows.empty:
            last = float(rows["frame"].max())
            within = rows[rows["frame"] <= budget]
            if not within.empty:
                pick = within.loc[within["frame"].idxmax()]
                frame = float(pick["frame"])
                value = pd.to_numeric(pd.Series([pick[metric]]), errors="coerce").iloc[0]
                score = float(value) * (100.0 if metric == "success" else 1.0)
        train_frames = run.train_frames if run.train_frames is not None else -1
        reached = (not math.isnan(last) and last >= budget) or (
            run.status == "done" and not pd.isna(train_frames) and train_frames >= budget
        )
        row.update(metric=metric, score=score, frame=frame, reached=bool(reached), last_frame=last)
        out.append(row)
    return pd.DataFrame(out, columns=cols)


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
    number of seeds per point is kept by the callers.
    """
    cols = [*IDENTITY, "frame", "value"]
    if results.eval.empty:
        return pd.DataFrame(columns=cols)
    if grid is None:
        grid = common_grid(results.eval, step=step)
    parts = []
    for _run_id, rows in results.eval.groupby("run_id", sort=False):
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


def best_online_returns(
    results: Results, method: str = "TACO", prefer: tuple[str, ...] = ("main",)
) -> dict[str, float]:
    """Per task, the best evaluation return reached during online training of ``method``.

    This is the paper's offline normaliser ("dividing the offline RL reward by the best reward we get
    during online TACO training"): the maximum over all evaluations of the online runs of that method on
    the task, from the ``prefer`` experiments (the main comparison) when they have runs on the task,
    else from any experiment (offline runs, which carry a dataset, are never used).
    """
    ev = results.eval
    if ev.empty:
        return {}
    online = ev[(ev["method"] == method) & ev["dataset"].isna()]
    out: dict[str, float] = {}
    for task, rows in online.groupby("task"):
        preferred = rows[rows["experiment"].isin(prefer)]
        best = (preferred if not preferred.empty else rows)["episode_reward"].max()
        if not math.isnan(best):
            out[str(task)] = float(best)
    return out


def normalize_offline(
    scores: pd.DataFrame, normalizers: dict[str, float]
) -> pd.DataFrame:
    """Offline rows of ``scores`` with ``normalized`` = 100 x score / best online TACO return of the task.

    Rows whose task has no normaliser get NaN (and the table says which normaliser is missing).
    """
    off = scores[scores["dataset"].notna()].copy()
    off["normalizer"] = off["task"].map(normalizers)
    off["normalized"] = 100.0 * off["score"] / off["normalizer"]
    return off
