"""A claim's cells: the values per cell (task x method, or task x dataset x method) that its rule reads, either from
the user's runs (:func:`observed_cells`) or drawn from where the paper gives them (:class:`CellSource`), for the power
simulation (analysis/power.py). The claims name their cells and their sources in their specs (analysis/claims/);
this module is what both sides build them from.

Where a cell's truth comes from:

- DrQ-v2 on a DMC task with a published curve: the DrQ-v2 authors' per-seed values, interpolated at the claim's
  budget (analysis.calibration.published_values), shifted so that their mean is the paper's mean, and drawn with
  replacement (clipped to the task's return range). Their spread is the real seed-to-seed spread.
- every other cell: normal with the paper's mean and std over its seeds, truncated at the task's return range (DMC
  returns [0, 1000]; normalised offline scores >= 0).
- a baseline the claim reads from the paper itself (the published DrQ-v2 curves against which
  ``online_avg_gain_vs_published`` is read) is fixed, not drawn.
- a solved / not solved cell (manipulator): each seed solves with the proportion the paper's prose gives (appendix G:
  its counts in repro_data/paper/claim_numbers.csv).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import special as sc
from scipy import stats as sps

from analysis.calibration import published_values
from analysis.claim_budget import frames_text
from analysis.context import Context
from analysis.paper import OFFLINE_TASKS
from repro.config.schema import DatasetKind

DMC_RANGE = (0.0, 1000.0)
NORMALIZED_RANGE = (0.0, math.inf)

Key = tuple
Cells = dict[Key, np.ndarray]  # one draw, or the runs: cell -> values over its seeds


@dataclass(frozen=True)
class CellSource:
    """Where one cell's values come from: ``kind`` is "normal" (the paper's mean and std, truncated at
    ``low``/``high``), "published" (the published per-seed ``values``, shifted to ``mean``, resampled),
    "bernoulli" (solved with probability ``mean``) or "fixed" (``values`` as they are, never drawn)."""

    key: Key
    kind: str
    mean: float
    std: float
    low: float = -math.inf
    high: float = math.inf
    values: tuple[float, ...] = ()
    source: str = ""

    def draw(self, rng: np.random.Generator, sims: int, n: int) -> np.ndarray:
        """A (sims x n) array of values: n seeds in each of ``sims`` draws."""
        if self.kind == "fixed":
            return np.broadcast_to(np.asarray(self.values, dtype=float), (sims, len(self.values)))
        if n == 0:
            return np.empty((sims, 0))
        if self.kind == "published":
            shifted = np.clip(np.asarray(self.values) + (self.mean - float(np.mean(self.values))),
                              self.low, self.high)
            return rng.choice(shifted, size=(sims, n), replace=True)
        if self.kind == "bernoulli":
            return (rng.random((sims, n)) < self.mean).astype(float)
        if not self.std > 0:
            return np.full((sims, n), self.mean)
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        if not a < b:
            return sps.truncnorm.rvs(a, b, loc=self.mean, scale=self.std, size=(sims, n), random_state=rng)
        return _truncnorm_rvs(rng, a, b, (sims, n)) * self.std + self.mean

    def describe(self) -> str:
        """The distribution, in words, as the cells table states it."""
        if self.kind == "published":
            return (f"published DrQ-v2 per-seed values (n={len(self.values)}, std {np.std(self.values, ddof=1):.1f}) "
                    f"shifted to mean {self.mean:g}, resampled, clipped to [{self.low:g}, {self.high:g}]")
        if self.kind == "bernoulli":
            return f"each seed solves with probability {self.mean:.3g}"
        if self.kind == "fixed":
            return f"fixed (not drawn): {len(self.values)} value(s), mean {np.mean(self.values):.1f}"
        return f"normal({self.mean:g}, {self.std:g}) truncated to [{self.low:g}, {self.high:g}]"


def _truncnorm_rvs(rng: np.random.Generator, a: float, b: float, size: tuple[int, int]) -> np.ndarray:
    """``scipy.stats.truncnorm.rvs(a, b, size=size, random_state=rng)`` for scalar ``a < b``: the same uniforms from
    ``rng``, the same values to the last bit (tests/test_plan.py compares them), in a fraction of the time. scipy
    broadcasts ``a`` and ``b`` to ``size`` and computes the truncation's constants (the log CDF at the bound, the
    log of the mass between the bounds) for every value; here they are computed once. Its log-sum-exp of two terms
    (``scipy.special.logsumexp``: the larger term plus log1p of the exponential of their difference; where that
    is not finite, the log of the sum of the exponentials) is written out for the pair. Only scipy.special's public
    functions are used (:func:`_log_mass`)."""
    q = rng.uniform(size=size).ravel()
    lower = a < 0  # scipy's branch: the inverse CDF from the left tail, or from the right one (by symmetry)
    bound = sc.log_ndtr(np.array([a if lower else -b]))
    mass = np.array([_log_mass(a, b)])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        term = (np.log(q) if lower else np.log1p(-q)) + mass
        high, low = np.maximum(bound, term), np.minimum(bound, term)
        log_phi = np.log1p(np.exp(low - high)) + high
        odd = ~np.isfinite(log_phi)
        if odd.any():
            log_phi[odd] = np.log(np.exp(np.broadcast_to(bound, term.shape)[odd]) + np.exp(term[odd]))
    x = sc.ndtri_exp(log_phi)
    return (x if lower else -x).reshape(size)


def _log_mass(a: float, b: float) -> float:
    """The log of the standard normal's mass between ``a < b``, computed as scipy's truncated normal computes it
    (the same operations, so the same bits: tests/test_plan.py), from scipy.special's public functions: between two
    bounds in the left tail, the log of the difference of the two CDFs (a log-sum-exp with the second term negated,
    as a complex logarithm); in the right tail, the left tail's by symmetry; around zero, log1p of minus both
    tails."""
    if b <= 0:
        return float(np.real(sc.logsumexp([sc.log_ndtr(b), sc.log_ndtr(a) + np.pi * 1j])))
    if a > 0:
        return _log_mass(-b, -a)
    return float(sc.log1p(-sc.ndtr(a) - sc.ndtr(-b)))


# ---------------------------------------------------------------- cells from runs
def means_table(cells: Cells) -> dict[Key, tuple[int, float]]:
    """(seeds, mean) per cell: analysis.claims.means of the runs."""
    return {k: (len(v), float(np.mean(v))) for k, v in cells.items() if len(v)}


def stacked(cells: Cells, keys: Sequence[Key]) -> np.ndarray:
    """A (seeds x cells) matrix as analysis.stats.score_matrix builds it: every cell cut to the fewest seeds."""
    k = min(len(cells[key]) for key in keys)
    return np.stack([cells[key][:k] for key in keys], axis=1)


def observed_cells(df: pd.DataFrame, keys: Sequence[str], value: str = "score") -> Cells:
    """The values of the runs that reached the budget, per cell, in seed order."""
    out: Cells = {}
    if df.empty:
        return out
    ok = df[df["reached"].astype(bool) & df[value].notna()].sort_values("seed")
    for key, rows in ok.groupby(list(keys)):
        out[key if isinstance(key, tuple) else (key,)] = rows[value].to_numpy(dtype=float)
    return out


# ---------------------------------------------------------------- cells from the paper
def paper_normal(key: Key, mean: float, std: float, where: str, low: float = DMC_RANGE[0],
                 high: float = DMC_RANGE[1]) -> CellSource:
    """A cell drawn from the paper's mean ± std, truncated at the return range."""
    return CellSource(key, "normal", mean, std, low, high, source=f"{where}: {mean:g} ± {std:g}")


def drqv2_cell(ctx: Context, task: str, budget: float, key: Key) -> CellSource:
    """DrQ-v2 on a DMC task: the published per-seed values at ``budget`` (where they exist) with Table 1's mean,
    else Table 1's mean ± std."""
    printed = ctx.paper.online_value(task, "DrQ-v2")
    assert printed is not None, task  # Table 1 has DrQ-v2 on every DMC task
    pub = published_values(ctx.published, task, budget)
    if len(pub) >= 2:
        return CellSource(key, "published", printed[0], float(np.std(pub, ddof=1)), *DMC_RANGE,
                          values=tuple(float(v) for v in pub),
                          source=f"Table 1 mean {printed[0]:g}; spread: published curves at {frames_text(budget)}")
    return paper_normal(key, printed[0], printed[1], "Table 1")


def table1_cells(ctx: Context, tasks: Sequence[str], method: str = "TACO") -> list[CellSource]:
    """``method``'s cells of Table 1 on ``tasks``: its mean ± std."""
    out = []
    for t in tasks:
        v = ctx.paper.online_value(t, method)
        assert v is not None, (t, method)  # Table 1 has every method on every DMC task
        out.append(paper_normal((t, method), v[0], v[1], "Table 1"))
    return out


def published_fixed_cells(ctx: Context, tasks: Sequence[str], budget: float) -> list[CellSource]:
    """The published DrQ-v2 curves at ``budget`` as they are (key (task, "published")), never drawn."""
    return [CellSource((t, "published"), "fixed", math.nan, math.nan,
                       values=tuple(float(v) for v in published_values(ctx.published, t, budget)),
                       source=f"published DrQ-v2 curves at {frames_text(budget)}, as published") for t in tasks]


def table2_cells(ctx: Context, tasks: Sequence[str]) -> list[CellSource]:
    """TACO's cells of Table 1 and every other objective's of Table 2 (where it prints a value) on ``tasks``."""
    out = table1_cells(ctx, tasks)
    for t in tasks:
        for m in ctx.paper.repr_others:
            v = ctx.paper.repr_value(t, m)
            if v is not None:
                out.append(paper_normal((t, m), v[0], v[1], "Table 2"))
    return out


def table3_cells(ctx: Context, methods: Sequence[str]) -> list[CellSource]:
    """``methods``' cells of Table 3 (normalised scores) on its task/dataset pairs."""
    return [paper_normal((r.task, r.dataset, r.method), float(r.normalized_mean), float(r.normalized_std),
                         "Table 3 (normalised)", *NORMALIZED_RANGE)
            for r in ctx.paper.offline.itertuples(index=False)
            if r.task in OFFLINE_TASKS and r.dataset in DatasetKind.values() and r.method in methods
            and pd.notna(r.normalized_mean)]


def solved_cells(ctx: Context, claim: str, counts: dict[str, str]) -> list[CellSource]:
    """Solved / not solved cells (key (label,)): each of ``label``'s seeds solves with the proportion the paper's
    prose gives for ``claim`` (its number ``counts[label]`` of its number "seeds", claim_numbers.csv)."""
    paper = ctx.paper
    seeds = paper.claim_number(claim, "seeds")
    where = paper.claims.set_index("id").loc[claim, "where"]
    out = []
    for label, name in counts.items():
        solved = paper.claim_number(claim, name)
        out.append(CellSource((label,), "bernoulli", solved / seeds, math.nan,
                              source=f"{where}: {solved:g} of {seeds:g} seeds solve"))
    return out


def solve_upper_bound(solved: int, seeds: int, level: float = 0.95) -> float:
    """The one-sided Clopper-Pearson upper bound on a solve probability from ``solved`` of ``seeds`` (0 of 6: 39%)."""
    return 1.0 if solved >= seeds else float(sps.beta.ppf(level, solved + 1, seeds - solved))
