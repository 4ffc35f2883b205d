"""Statistics: mean +- std over seeds, bootstrap CIs and rliable aggregates.

* ``std`` is the sample standard deviation over seeds, ``ddof=1`` (:data:`DDOF`); undefined for n < 2.
* Every confidence interval is a 95% percentile stratified-bootstrap CI, rliable's
  ``rliable.library.get_interval_estimates`` computed as whole-array operations by :mod:`analysis.bootstrap`
  (equal to rliable's for the same random state: the same indices, the same statistics, the same percentiles;
  tests/test_bootstrap.py checks it against rliable itself). Per-cell CIs of a mean over seeds are the one-task
  case: cells with the same number of seeds are bootstrapped together as the columns of one matrix, so each
  column is resampled over its own runs.
* Reproducibility: rliable draws its bootstrap indices from NumPy's *global* legacy generator seeded with the
  random state (:func:`seeded`: how the tests run rliable itself as the reference); the
  vectorized bootstrap draws the same stream from its own ``RandomState(seed)`` and leaves the global one
  alone. Each method / cell group is seeded separately, so adding a method does not change another's CI.
* Aggregates (IQM, mean, optimality gap with gamma = 1) are over normalised scores: DMC returns / 1000
  (the maximum episode return of a DMC task), Meta-world success rates / 100.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis import bootstrap as bs
from analysis.defaults import DEFAULT_REPS, DEFAULT_SEED

DDOF = 1
PROFILE_REPS = 2_000  # rliable's default for create_performance_profile
# rliable's probability of improvement ran scipy's Mann-Whitney U per task per repetition (about 20 ms per
# repetition for 9 tasks on one CPU core), so F1's CI of it used fewer repetitions; kept so the figure's numbers
# stay those it printed.
POI_REPS = 1_000
CI_SIZE = bs.CI_SIZE
ESTIMATOR = bs.ESTIMATOR
SCORE_SCALE = {"episode_reward": 1000.0, "success": 100.0}


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[np.random.RandomState]:
    """Seed NumPy's global generator (which rliable uses) for the duration of the block."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():
            # arch deprecates its random_state argument, which rliable passes through.
            warnings.simplefilter("ignore", FutureWarning)
            yield np.random.RandomState(seed)
    finally:
        np.random.set_state(state)


@dataclass(frozen=True)
class CellStats:
    """Summary of one table cell: seeds, mean, std (ddof=1) and the 95% CI of the mean."""

    n: int
    mean: float
    std: float
    ci_low: float
    ci_high: float

    def contains(self, value: float | None) -> bool | None:
        """Whether ``value`` lies inside the CI (None if the CI or the value is undefined)."""
        if value is None or math.isnan(value) or math.isnan(self.ci_low):
            return None
        return bool(self.ci_low <= value <= self.ci_high)


def mean_std(values: Sequence[float] | np.ndarray) -> tuple[int, float, float]:
    """(n, mean, std with ddof=1) of the finite values; NaN mean for n = 0 and NaN std for n < 2."""
    arr = np.asarray(values, dtype=float)
    arr = arr[np.isfinite(arr)]
    n = len(arr)
    mean = float(arr.mean()) if n else math.nan
    std = float(arr.std(ddof=DDOF)) if n > DDOF else math.nan
    return n, mean, std


def mean_cis(
    columns: Sequence[np.ndarray], reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> list[tuple[float, float]]:
    """95% bootstrap CI of the mean of each column (values over seeds), as rliable computes it.

    Columns are grouped by their number of finite values; each group is one bootstrap (rliable's) of a
    (n_seeds x n_columns) matrix with a per-column mean as the statistic. Columns with fewer than 2
    values get (NaN, NaN).
    """
    clean = [np.asarray(c, dtype=float)[np.isfinite(np.asarray(c, dtype=float))] for c in columns]
    out: list[tuple[float, float]] = [(math.nan, math.nan)] * len(clean)
    by_n: dict[int, list[int]] = {}
    for i, col in enumerate(clean):
        if len(col) >= 2:
            by_n.setdefault(len(col), []).append(i)
    for n in sorted(by_n):
        idx = by_n[n]
        matrix = np.stack([clean[i] for i in idx], axis=1)
        _, (lows, highs) = bs.interval_estimates(bs.COLUMN_MEAN, [matrix], reps, seed)
        for j, i in enumerate(idx):
            out[i] = (float(lows[j]), float(highs[j]))
    return out


AGGREGATE_NAMES = ("IQM", "Mean", "Optimality Gap")


def aggregate_estimates(
    score_dict: Mapping[str, np.ndarray], reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> pd.DataFrame:
    """rliable's IQM, mean and optimality gap with 95% stratified-bootstrap CIs (:mod:`analysis.bootstrap`).

    ``score_dict`` maps a method to a normalised (n_runs x n_tasks) matrix. Returns a long table:
    method, metric, value, ci_low, ci_high.
    """
    rows = []
    for method, scores in score_dict.items():
        points, cis = bs.interval_estimates(bs.AGGREGATES, [scores], reps, seed)
        for k, name in enumerate(AGGREGATE_NAMES):
            rows.append(
                {
                    "method": method,
                    "metric": name,
                    "value": float(points[k]),
                    "ci_low": float(cis[0][k]),
                    "ci_high": float(cis[1][k]),
                }
            )
    return pd.DataFrame(rows, columns=["method", "metric", "value", "ci_low", "ci_high"])


def performance_profiles(
    score_dict: Mapping[str, np.ndarray],
    taus: np.ndarray,
    reps: int = PROFILE_REPS,
    seed: int = DEFAULT_SEED,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """rliable run-score performance profiles (``create_performance_profile``, its global generator seeded with
    ``seed``): method -> (profile over ``taus``, 2 x len(taus) CI)."""
    stat = bs.score_distribution(taus)
    out = {}
    for method, scores in score_dict.items():
        profile, cis = bs.interval_estimates(stat, [scores], reps, seed)
        out[method] = (np.asarray(profile), np.asarray(cis))
    return out


def _interval(scores: np.ndarray | list[np.ndarray], statistic: bs.Statistic, reps: int,
              seed: int) -> tuple[float, float, float]:
    """One scalar ``statistic`` of ``scores`` (a runs x tasks matrix, or a list of them passed as its arguments)
    with its 95% percentile stratified-bootstrap CI, as rliable computes it: (value, ci_low, ci_high).

    ``reps`` 0: the value alone (``statistic`` of the data), with a NaN CI; the power simulation
    (analysis.power) reads rules whose verdict is the point estimate this way."""
    arrays = scores if isinstance(scores, list) else [scores]
    if reps == 0:
        return float(statistic.point(*[np.asarray(a, dtype=float) for a in arrays])[0]), math.nan, math.nan
    point, cis = bs.interval_estimates(statistic, arrays, reps, seed)
    return float(point[0]), float(cis[0][0]), float(cis[1][0])


def probability_of_improvement(
    x: np.ndarray, y: np.ndarray, reps: int = POI_REPS, seed: int = DEFAULT_SEED
) -> tuple[float, float, float]:
    """P(X > Y) over tasks (rliable's probability_of_improvement) with its 95% CI: (value, ci_low, ci_high).

    ``x`` and ``y`` are (n_runs x n_tasks) matrices over the same tasks; runs may differ in number. The same as
    :func:`poi_interval` (its fewer default repetitions are those F1 has printed).
    """
    return _interval([x, y], bs.PROBABILITY_OF_IMPROVEMENT, reps, seed)


def pairwise_poi(x: np.ndarray, y: np.ndarray) -> float:
    """rliable's probability of improvement P(X > Y) (``rliable.metrics.probability_of_improvement``: per task
    the Mann-Whitney U of X over Y divided by m x n, ties counting a half; averaged over tasks), computed by
    counting pairs in NumPy instead of one scipy call per task."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    diff = x[:, None, :] - y[None, :, :]  # (m, n, tasks)
    per_task = ((diff > 0).sum(axis=(0, 1)) + 0.5 * (diff == 0).sum(axis=(0, 1))) / (x.shape[0] * y.shape[0])
    return float(per_task.mean())


def poi_interval(
    x: np.ndarray, y: np.ndarray, reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> tuple[float, float, float]:
    """:func:`probability_of_improvement` at rliable's default repetitions: (value, ci_low, ci_high) by rliable's
    stratified bootstrap."""
    return _interval([x, y], bs.PROBABILITY_OF_IMPROVEMENT, reps, seed)


def ratio_of_means(
    x: np.ndarray, y: np.ndarray, reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> tuple[float, float, float]:
    """mean(x) / mean(y) over all runs and tasks, with a 95% stratified-bootstrap CI (as rliable; ``reps`` 0: the
    ratio alone)."""
    return _interval([x, y], bs.RATIO_OF_MEANS, reps, seed)


def score_matrix(
    scores: pd.DataFrame, tasks: Sequence[str], value: str = "score"
) -> tuple[np.ndarray | None, str]:
    """A (n_runs x n_tasks) matrix from one method's per-run rows, as rliable needs.

    If tasks have different numbers of seeds, every task keeps its ``min`` lowest seeds and the note
    says how many runs were left out; None if a task has no run.
    """
    per_task = []
    for task in tasks:
        rows = scores[(scores["task"] == task) & scores[value].notna()].sort_values("seed")
        per_task.append(rows[value].to_numpy(dtype=float))
    counts = [len(v) for v in per_task]
    if not counts or min(counts) == 0:
        missing = [t for t, c in zip(tasks, counts) if c == 0]
        return None, f"no runs on {', '.join(missing)}"
    k = min(counts)
    dropped = sum(counts) - k * len(counts)
    note = f"{k} runs per task" + (f"; {dropped} extra runs left out to balance seeds across tasks" if dropped else "")
    return np.stack([v[:k] for v in per_task], axis=1), note


def grand_mean_ci(matrix: np.ndarray, reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED) -> tuple[float, float, float]:
    """Mean over runs and tasks of a (n_runs x n_tasks) matrix with its 95% stratified-bootstrap CI."""
    return _interval(matrix, bs.MEAN, reps, seed)


def grand_mean_cis(matrices: np.ndarray, reps: int = DEFAULT_REPS,
                   seed: int = DEFAULT_SEED) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`grand_mean_ci` of every draw: ``matrices`` (draws, runs, tasks) gives the means, CI lows and CI highs,
    each (draws,), each draw's equal to :func:`grand_mean_ci` of its matrix (``reps`` 0: the means, NaN CIs)."""
    m = np.asarray(matrices, dtype=float)
    if reps == 0:
        means = bs.MEAN.vector(m)[:, 0]
        return means, np.full(len(means), math.nan), np.full(len(means), math.nan)
    points, cis = bs.draw_intervals(bs.MEAN, [m], reps, seed)
    return points[:, 0], cis[0, :, 0], cis[1, :, 0]


def difference_of_means(
    x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray, reps: int = DEFAULT_REPS,
    seed: int = DEFAULT_SEED,
) -> tuple[float, float, float]:
    """mean(x) - mean(y) of two independent samples (values over seeds) with its 95% percentile bootstrap CI:
    rliable's stratified independent bootstrap resamples each sample over its own seeds (the one-task case)."""
    a = np.asarray(x, dtype=float).reshape(-1, 1)
    b = np.asarray(y, dtype=float).reshape(-1, 1)
    return _interval([a, b], bs.DIFFERENCE_OF_MEANS, reps, seed)


def ratio_to_task_means(
    x: np.ndarray, ys: Sequence[Sequence[float] | np.ndarray], reps: int = DEFAULT_REPS, seed: int = DEFAULT_SEED
) -> tuple[float, float, float]:
    """mean(x) / (mean over tasks of each task's mean of ``ys``) with a 95% stratified-bootstrap CI (rliable).

    ``x`` is a (n_runs x n_tasks) matrix; ``ys`` one array of values over seeds per task, each with its own
    number of seeds (no seed is dropped to balance them); every array is resampled independently over its
    own seeds. A one-row ``x`` (e.g. a paper's printed means) is a constant numerator. ``reps`` 0: the ratio
    alone."""
    num = np.asarray(x, dtype=float)
    dens = [np.asarray(y, dtype=float).reshape(-1, 1) for y in ys]
    return _interval([num, *dens], bs.RATIO_TO_TASK_MEANS, reps, seed)
