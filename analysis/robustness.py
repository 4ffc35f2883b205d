"""Seed robustness (F11) and task solving (F12) summaries from per-run scores and curves."""

from __future__ import annotations

import numpy as np
import pandas as pd

BROKEN_FRACTION = 0.5  # a seed is "broken" if its score is below half the median of its cell's seeds
SOLVED_RETURN = 500.0  # manipulator bring_ball counts as solved once an evaluation return reaches this


def seed_spread(df: pd.DataFrame, keys: tuple[str, ...] = ("task", "label")) -> pd.DataFrame:
    """Per cell over the runs that reached the budget: n, mean, std (ddof=1), min, max, broken seeds."""
    rows = []
    ok = df[df["reached"].astype(bool)] if not df.empty else df
    for key, cell in ok.groupby(list(keys)) if not ok.empty else []:
        rows.append({**dict(zip(keys, key if isinstance(key, tuple) else (key,))),
                     **cell_spread(cell["score"].to_numpy(dtype=float))})
    return pd.DataFrame(rows, columns=[*keys, "n", "mean", "std", "min", "max", "broken"])


def cell_spread(values: np.ndarray) -> dict[str, float]:
    """One cell's seeds: n, mean, std (ddof=1; NaN for one seed), min, max and broken seeds
    (:func:`broken_seeds`)."""
    s = np.asarray(values, dtype=float)
    return {"n": len(s), "mean": float(s.mean()), "std": float(seed_std(s)), "min": float(s.min()),
            "max": float(s.max()), "broken": int(broken_seeds(s))}


def seed_std(values: np.ndarray) -> np.ndarray:
    """The std over the seeds (the last axis; ddof=1) of each cell, NaN for one seed: ``values`` (..., seeds), e.g. a
    claim's cell in every draw of the power simulation (draws, seeds), gives (...)."""
    s = np.asarray(values, dtype=float)
    return s.std(ddof=1, axis=-1) if s.shape[-1] > 1 else np.full(s.shape[:-1], np.nan)


def broken_seeds(values: np.ndarray) -> np.ndarray:
    """The broken seeds of each cell: those below :data:`BROKEN_FRACTION` of the median of its seeds (the last axis
    of ``values``, (..., seeds)), none where that median is not positive; (...) counts."""
    s = np.asarray(values, dtype=float)
    med = np.median(s, axis=-1)
    return np.where(med > 0, (s < BROKEN_FRACTION * med[..., None]).sum(axis=-1), 0)


def solved_counts(curves_or_eval: pd.DataFrame, max_frame: float, threshold: float = SOLVED_RETURN,
                  value: str = "value") -> pd.DataFrame:
    """Per label: runs, runs that reached ``threshold`` at some frame <= ``max_frame``, last frame seen."""
    rows = []
    if curves_or_eval.empty:
        return pd.DataFrame(columns=["label", "runs", "solved", "last_frame"])
    for label, cell in curves_or_eval.groupby("label"):
        within = cell[cell["frame"] <= max_frame]
        per_run = within.groupby("run_id")[value].max()
        rows.append({"label": label, "runs": cell["run_id"].nunique(), "solved": int((per_run >= threshold).sum()),
                     "last_frame": float(cell["frame"].max())})
    return pd.DataFrame(rows, columns=["label", "runs", "solved", "last_frame"])
