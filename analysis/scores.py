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

from analysis.comparable import reached
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
    ``reached`` is true if the run has an evaluation at or past the budget (analysis.comparable.reached: by evidence,
    not by its configured ``train.frames``); runs that did not reach it keep their score (at an earlier frame) but
    are flagged, and the tables count them separately.

    Offline runs (a dataset) are scored at their own budget, whatever ``budget`` says: the evaluation at the
    largest update <= the run's ``offline.updates`` (``update``), its return as ``score`` and the normalised
    score the run recorded (``normalized``, eval.csv's ``normalized_score``, with its ``score_reference``);
    ``reached`` when the run is done and evaluated at its ``offline.updates``. Online rows have no
    ``normalized``; offline rows no ``frame``.

    ``budget``: the budget a row is scored at (online: ``budget``, in environment frames; offline: the run's
    ``offline.updates``), which analysis.comparable compares with the paper's.
    """
    cols = [*IDENTITY, "metric", "score", "frame", "reached", "last_frame", "normalized", "score_reference",
            "update", "last_update", "budget"]
    if results.runs.empty:
        return pd.DataFrame(columns=cols)
    runs, ev = results.runs, results.eval
    offline = runs["dataset"].notna()
    # every run's pick at once (one pass over the evaluations per kind of run, not one per run)
    on_last, on_pick = _picks(ev, runs.loc[~offline, "run_id"], "frame", lambda rows: pd.Series(float(budget),
                                                                                                 index=rows.index),
                              ["frame", "episode_reward", "success"])
    budgets = runs.loc[offline].set_index("run_id")["offline_updates"]
    off_last, off_pick = _picks(ev, runs.loc[offline, "run_id"], "update",
                                lambda rows: pd.to_numeric(rows["run_id"].map(budgets), errors="coerce"),
                                ["episode_reward", "update", "normalized_score", "score_reference"])
    out = []
    # each run's identity values as runs.itertuples() gives them (one list per column, not one getattr per value)
    for values in zip(*(list(runs[k]) for k in IDENTITY)):
        row = dict(zip(IDENTITY, values))
        run_id = row["run_id"]
        if not pd.isna(row["dataset"]):
            row.update(_offline_score(row, off_last.get(run_id), off_pick.get(run_id)),
                       budget=math.nan if pd.isna(row["offline_updates"]) else float(row["offline_updates"]))
            out.append(row)
            continue
        metric = metric_of(row["suite"])
        score, frame = math.nan, math.nan
        last = on_last.get(run_id, math.nan)
        pick = on_pick.get(run_id)
        if pick is not None:
            frame = float(pick["frame"])
            score = _number(pick[metric]) * (100.0 if metric == "success" else 1.0)
        row.update(metric=metric, score=score, frame=frame, reached=reached(last, budget), last_frame=last,
                   normalized=math.nan, score_reference=None, update=math.nan, last_update=math.nan,
                   budget=float(budget))
        out.append(row)
    return pd.DataFrame(out, columns=cols)


def _picks(ev: pd.DataFrame, run_ids: pd.Series, x: str, limits: Any,
           columns: list[str]) -> tuple[dict[str, float], dict[str, dict[str, Any]]]:
    """For the runs ``run_ids``: (run -> its largest ``x``, run -> the ``columns`` of its evaluation row at the largest
    ``x`` within its budget prefix (:func:`_at_budget`; ``limits(rows)`` gives each row's run budget, NaN: no limit),
    each value as ``DataFrame.iterrows`` gives it). A run without evaluations is in neither."""
    if ev.empty or run_ids.empty:
        return {}, {}
    # only the columns used here: filtering the whole eval table would copy every column
    used = [c for c in dict.fromkeys(["run_id", x, "budget_end", *columns]) if c in ev.columns]
    rows = ev.loc[ev["run_id"].isin(set(run_ids)), used]
    if rows.empty:
        return {}, {}
    last = {str(k): float(v) for k, v in rows.groupby("run_id", sort=False)[x].max().items()}
    limit = limits(rows)
    at = rows[x]
    keep = limit.isna() | ((at <= limit) & (~_budget_end(rows) | (at == limit)))
    within = rows[keep & at.notna()]
    if within.empty:
        return last, {}
    idx = within.groupby("run_id", sort=False)[x].idxmax()
    picked = within.loc[idx.to_numpy()]
    names = [c for c in columns if c in picked.columns]
    # one list per column instead of one Series per row (iterrows): the same Python values
    values = [list(picked[c]) for c in names]
    return last, {str(r): dict(zip(names, vals)) for r, *vals in zip(picked["run_id"], *values)}


def _number(value: Any) -> float:
    """``value`` as a float, as ``pd.to_numeric(pd.Series([value]), errors="coerce")`` reads it (a float as it is)."""
    if type(value) is float:
        return value
    return float(pd.to_numeric(pd.Series([value]), errors="coerce").iloc[0])


def _offline_score(run: dict[str, Any], last: float | None, pick: dict[str, Any] | None) -> dict[str, Any]:
    """The score columns of one offline run (its identity values) at its own budget (see :func:`final_scores`):
    ``last`` its largest evaluated update, ``pick`` its evaluation at the largest update within its budget."""
    out: dict[str, Any] = {"metric": "episode_reward", "score": math.nan, "frame": math.nan, "reached": False,
                           "last_frame": math.nan, "normalized": math.nan, "score_reference": None,
                           "update": math.nan, "last_update": math.nan}
    if last is None:
        return out
    budget = run["offline_updates"]
    out["last_update"] = last
    if pick is None:
        return out
    reference = pick["score_reference"]
    out.update(score=float(pick["episode_reward"]), update=float(pick["update"]),
               normalized=_number(pick["normalized_score"]),
               score_reference=None if pd.isna(reference) else str(reference),
               reached=bool(run["status"] == "done" and not pd.isna(budget) and reached(last, budget)))
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
    # every run at once: the rows ordered by run (in order of first appearance) and frame, each run a slice
    codes = pd.factorize(online["run_id"], sort=False)[0]
    frames_all = online["frame"].to_numpy(dtype=float)
    order = np.lexsort((frames_all, codes))
    codes, frames_all = codes[order], frames_all[order]
    suites = online["suite"].to_numpy()[order]
    by_metric = {m: _values(online, m).to_numpy(dtype=float)[order] for m in ("episode_reward", "success")}
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    ends = np.r_[starts[1:], len(codes)]
    firsts, frames, values = [], [], []
    for start, end in zip(starts.tolist(), ends.tolist()):
        run_values = by_metric[metric_of(suites[start])][start:end]
        ok = ~np.isnan(run_values)
        if not ok.any():
            continue
        f, v = frames_all[start:end][ok], run_values[ok]
        g = grid[(grid >= f[0]) & (grid <= f[-1])]
        firsts.append(start)
        frames.append(g)
        values.append(np.interp(g, f, v))
    if not firsts:
        return pd.DataFrame(columns=cols)
    counts = np.array([len(g) for g in frames])
    first_rows = order[np.array(firsts)]
    columns: dict[str, Any] = {key: _repeat_first(online[key], first_rows, counts) for key in IDENTITY}
    columns.update(frame=np.concatenate(frames), value=np.concatenate(values))
    return pd.DataFrame(columns)[cols]


def _repeat_first(column: pd.Series, rows: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Each run's value of an identity ``column`` (at its position in ``rows``) repeated for its ``counts`` curve
    points, in the type concatenating one frame per run (each built from the run's scalar) gives: an object column
    whose runs all hold integers is int64, one of integers and floats float64, and so on."""
    picked = column.to_numpy()[rows]
    if picked.dtype != object:
        return np.repeat(picked, counts)
    kinds: dict[type, Any] = {}
    for value in picked:
        kinds.setdefault(type(value), value)
    dtype = pd.concat([pd.DataFrame({"v": [value]}) for value in kinds.values()], ignore_index=True)["v"].dtype
    repeated = np.repeat(picked, counts)
    return repeated if dtype == np.dtype(object) else repeated.astype(dtype)
