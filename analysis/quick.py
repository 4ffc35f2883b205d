"""Learning curves of any set of runs (`repro plot`): runs loaded with the report's loader, one tidy table.

Each argument is a results root or one run directory; both go through :func:`analysis.load.load_results`.
A metric of eval.csv comes from the loaded evaluation rows; any other metric is a train.csv column, read with
the same strict CSV reader (file name and required columns from repro/runs/runformat.py). Bad input raises
:class:`PlotInputError` with one line.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from analysis.comparable import ENV_KEYS
from analysis.load import IDENTITY, ResultsRootError, load_results, read_csv_strict
from repro.config.errors import UserError
from repro.runs.runformat import EVAL_COLUMNS, TRAIN, TRAIN_REQUIRED

# Names accepted by --by besides the identity columns of analysis/load.py.
BY_ALIASES = {"frames": "train_frames"}
NOT_METRICS = ("frame", "step", "update")  # x axes, not values


class PlotInputError(UserError, ValueError):
    """No runs, an unknown metric or an unknown grouping column."""


def load_runs(paths: Sequence[str | Path]) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(runs, eval rows, problem lines) of every run under ``paths``; ``run_id`` is the run folder's path."""
    runs, evals, problems = [], [], []
    for arg in paths:
        root = Path(arg)
        try:
            res = load_results(root)
        except ResultsRootError as exc:
            raise PlotInputError(str(exc)) from None
        problems += [str(p) for p in res.problems if p.level == "error"]
        if res.runs.empty:
            continue
        full = {rid: str((root / rid).resolve()) for rid in res.runs["run_id"]}
        runs.append(res.runs.assign(run_id=res.runs["run_id"].map(full)))
        if not res.eval.empty:
            evals.append(res.eval.assign(run_id=res.eval["run_id"].map(full)))
    if not runs:
        raise PlotInputError(f"no runs (folders with config.yaml) under {', '.join(str(p) for p in paths)}")
    all_runs = pd.concat(runs, ignore_index=True).drop_duplicates("run_id")
    all_eval = pd.concat(evals, ignore_index=True).drop_duplicates(["run_id", "frame"]) if evals else pd.DataFrame()
    return all_runs, all_eval, problems


def by_columns(by: str) -> list[str]:
    """``agent,variant`` -> identity columns (``agent``, ``variant``); PlotInputError for an unknown one."""
    names = [b.strip() for b in by.split(",") if b.strip()]
    if not names:
        raise PlotInputError("--by needs at least one column, e.g. --by agent,variant")
    known = [c for c in IDENTITY if c not in ("run_id", "status")]
    out = []
    for name in names:
        col = BY_ALIASES.get(name, name)
        if col not in known:
            raise PlotInputError(f"unknown --by column '{name}' (one of: {', '.join(sorted([*known, *BY_ALIASES]))})")
        out.append(col)
    return out


def _train_rows(runs: pd.DataFrame, metric: str) -> tuple[pd.DataFrame, set[str]]:
    """``metric`` from each run's train.csv: (rows run_id, frame, value), every column name seen."""
    rows, seen = [], set()
    for run_id in runs["run_id"]:
        path = Path(run_id) / TRAIN
        if not path.exists():
            continue
        try:
            df = read_csv_strict(path, TRAIN_REQUIRED)
        except (ValueError, OSError, UnicodeDecodeError, pd.errors.ParserError):
            continue  # load_results reported it
        seen.update(df.columns)
        if metric in df.columns:
            rows.append(pd.DataFrame({"run_id": run_id, "frame": df["frame"], "value": df[metric]}))
    return (pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=["run_id", "frame", "value"])), seen


def tidy_curves(runs: pd.DataFrame, evals: pd.DataFrame, metric: str, by: Sequence[str]) -> pd.DataFrame:
    """Columns task, seed, label, frame, value (one row per run and evaluation or training episode). A curve's
    label joins its ``by`` values, the algorithm shown by its method's label."""
    if metric in NOT_METRICS:
        raise PlotInputError(f"'{metric}' is the x axis, not a metric")
    if metric in EVAL_COLUMNS:
        values = evals[["run_id", "frame", metric]].rename(columns={metric: "value"}) if not evals.empty else None
    else:
        values, seen = _train_rows(runs, metric)
        if values.empty:
            names = sorted({*EVAL_COLUMNS, *seen} - {*NOT_METRICS, "run_id"})
            raise PlotInputError(f"unknown metric '{metric}' (eval.csv or train.csv columns: {', '.join(names)})")
    if values is None or values.empty:
        raise PlotInputError(f"no values of '{metric}' in the selected runs")
    values = values.assign(value=pd.to_numeric(values["value"], errors="coerce")).dropna(subset=["value"])
    meta = runs[["run_id", "task", "seed", *by]].copy()
    named = meta[list(by)].astype(str)
    if "agent" in by and "method" in runs.columns:
        # the method's registered label (analysis.identity.method_label, the loader's method column), not the
        # agent file's name: CQL+TACO for cql_taco, a plugin's own label for its agent
        named["agent"] = runs["method"].where(runs["method"].notna(), runs["agent"]).astype(str)
    meta["label"] = named.agg(" / ".join, axis=1)
    env = [c for c in (*ENV_KEYS, "suite") if c in runs.columns]  # to label runs of another environment
    out = values.merge(meta[["run_id", "task", "seed", "label"]].join(runs[env]), on="run_id", how="inner")
    if out.empty:
        raise PlotInputError(f"no values of '{metric}' in the selected runs")
    return out[["task", "seed", "label", "frame", "value", "run_id", *env]]


def repeated_seeds(curves: pd.DataFrame) -> list[str]:
    """``task / label`` cells where two runs share a seed (their curves would be averaged as one seed)."""
    per = curves.groupby(["task", "label", "seed"])["run_id"].nunique()
    return sorted({f"{t} / {lab}" for (t, lab, _), n in per.items() if n > 1})
