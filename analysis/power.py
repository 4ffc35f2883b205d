"""Statistical power of each claim before the runs: the probability that the claim's own rule, applied as
``repro claims`` applies it, says "supported" if the paper's numbers are the truth (``repro plan --claims``).

* **Cells.** Each simulated claim names its cells (task x method, or task x dataset x method) and where each
  cell's truth comes from (:class:`CellSource`):

  - DrQ-v2 on a DMC task with a published curve: the DrQ-v2 authors' per-seed values, interpolated at the
    claim's budget (analysis.calibration.published_values), shifted so that their mean is the paper's mean, and
    drawn with replacement (clipped to the task's return range). Their spread is the real seed-to-seed spread.
  - every other cell: normal with the paper's mean and std over its seeds, truncated at the task's return
    range (DMC returns [0, 1000]; normalised offline scores >= 0), written down per cell.
  - a baseline the claim reads from the paper itself (DreamerV3 and TD-MPC in Table 1, the published DrQ-v2
    curves against which ``online_avg_gain_vs_published`` is read) is fixed, not drawn.
  - manipulator: each seed solves the task with the paper's proportion (TACO 3/6, DrQ-v2 0/6).

* **Rule.** Each draw builds what the claim's check builds from runs (a ``means`` table of (seeds, mean) per
  cell, score matrices, per-cell spreads, solved counts) and calls the claim's rule in analysis.claims (the
  same function ``repro claims`` calls, with the same seed minimum and ``require``), so a cell with fewer
  seeds than the claim's minimum is "not enough data". Rules whose verdict reads a point estimate run with
  ``reps`` 0 (the point alone, the CI is only evidence); offline_average, whose verdict reads a bootstrap CI,
  runs rliable's bootstrap in every draw (:data:`CI_REPS` repetitions, fewer draws).

* **Monte-Carlo error.** The power p over S draws has standard error sqrt(p (1 - p) / S); every draw comes
  from one NumPy Generator seeded from (seed, claim, seeds per cell), so a fixed ``seed`` gives the same table.

* **Seeds for 80%.** The smallest seeds per cell (>= the claim's minimum, <= ``max_seeds``) whose simulated
  power is >= 80%: power at the minimum, then doubling, then bisection (the power of these rules grows with
  the seeds, up to the Monte-Carlo error).

* **Conditioned on runs** (:func:`conditioned_power`): the values of the seeds already done stay as they are in
  each cell; only the missing seeds are drawn from the cell's source.

A claim whose rule cannot be simulated from what is known (a learning-curve rule, a figure-only number, a
single run, a timing) is listed with the reason (:data:`NOT_SIMULATED`).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats as sps

from analysis import bootstrap as bs
from analysis import claims as cl
from analysis import select
from analysis.calibration import published_values
from analysis.claim_budget import ClaimBudget, frames_text, load_budgets
from analysis.context import Context
from analysis.load import Results
from analysis.offline_tables import offline_runs
from analysis.paper import DMC9, OFFLINE_TASKS, PaperData
from analysis.robustness import BROKEN_FRACTION, cell_spread
from analysis.tables import TableOutput, fmt_num, write_table
from repro.config.schema import DatasetKind

TARGET = 0.8  # the power "seeds for 80%" asks for
DEFAULT_SIMS = 2000
DEFAULT_MAX_SEEDS = 50
REPORT_SIMS, REPORT_MAX_SEEDS = 500, 20  # the report's section: fewer draws, a shorter search
CI_REPS = 300  # bootstrap repetitions per draw where the verdict reads a CI (offline_average)
CI_SIMS = 100  # draws of such a claim (each runs four bootstraps)
DMC_RANGE = (0.0, 1000.0)
NORMALIZED_RANGE = (0.0, math.inf)

Key = tuple
Cells = dict[Key, np.ndarray]  # one draw: cell -> values over its seeds
Draws = dict[Key, np.ndarray]  # every draw: cell -> (draws x its seeds)
# A claim's verdict in every draw at once, as its ``judge`` gives it draw by draw: an object array of verdicts,
# "" where a value the verdict compares lies within :data:`TIE` of its threshold (there the draw is judged one by
# one, so that a difference in the last bits of a whole-array sum cannot change a verdict).
BatchJudge = Callable[[Context, Draws], np.ndarray]
TIE = 1e-9  # relative distance from a threshold under which a draw is judged by ``judge`` itself

NOT_SIMULATED = {
    "reacher_speed": "its rule reads TACO's and DrQ-v2's mean learning curves up to 1.5M frames; the paper gives "
                     "TACO's curve only as a figure (F4), with no per-seed or per-frame numbers",
    "longer_training": "its rule reads both methods at 2M frames; the paper gives those only as learning-curve "
                       "figures (F4), with no numbers at 2M",
    "metaworld": "the paper gives Meta-world success rates only as figures (F5), with no mean or std per task",
    "action_repr_gain": "the paper gives the gains as percentages of a bar figure (F3) with no std over seeds",
    "no_action_repr_vs_drqv2": "the paper gives these as percentages of a bar figure (F3) with no std over seeds",
    "tsne_clusters": "one trained agent and a t-SNE embedding: not a statistic over seeds",
    "batch_size": "the paper gives the batch-size results only as a figure (F7a), with no numbers",
    "objective_removal": "the paper gives the ablation only as a figure (F7b), with no numbers",
    "horizon_choice": "the paper gives K=1 and K=3 only as a figure (F8), with no numbers",
    "action_repeat": "the paper gives the action-repeat results only as a figure (F9), with no numbers",
    "action_dim": "the paper gives the latent-dimension results only as a figure (appendix E), with no numbers",
    "speed": "a timing on your hardware (`repro bench`), not a statistic over seeds",
}


# ---------------------------------------------------------------- cell sources
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
        return sps.truncnorm.rvs(a, b, loc=self.mean, scale=self.std, size=(sims, n), random_state=rng)

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


# ---------------------------------------------------------------- simulated claims
@dataclass
class SimClaim:
    """One claim as the simulation runs it: its cells, a ``judge(ctx, cells) -> (verdict, evidence)`` that
    builds the check's input from one draw and calls the claim's rule, and the user's values per cell
    (``observed(ctx)``, from the runs that reached the claim's budget)."""

    id: str
    spec: ClaimBudget
    cells: list[CellSource]
    judge: Callable[[Context, Cells], tuple[str, str]]
    observed: Callable[[Context], Cells] | None = None
    tasks: tuple[str, ...] = ()  # the tasks of its runs (what its seeds cost)
    sims: int | None = None  # draws (default: the caller's)
    reps: int = 0  # bootstrap repetitions the rule runs in each draw
    notes: list[str] = field(default_factory=list)
    batch: BatchJudge | None = None  # the verdicts of all draws at once (see :data:`BatchJudge`)
    # simulate()'s results by its arguments: the table asks for the same power more than once (at the claim's
    # minimum, and first in the search for 80%)
    memo: dict[Hashable, Power] = field(default_factory=dict, repr=False, compare=False)


def means_table(cells: Cells) -> dict[Key, tuple[int, float]]:
    """What analysis.claims.means builds from runs: (seeds, mean) per cell."""
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


def _judge_gain(ctx: Context, cells: Cells) -> tuple[str, str]:
    cl.require(ctx, means_table(cells), [(t, m) for t in DMC9 for m in ("TACO", "DrQ-v2")])
    return cl.avg_gain_rule(ctx, stacked(cells, [(t, "TACO") for t in DMC9]),
                            stacked(cells, [(t, "DrQ-v2") for t in DMC9]))


def _judge_published_gain(ctx: Context, cells: Cells) -> tuple[str, str]:
    cl.require(ctx, means_table(cells), [(t, "TACO") for t in DMC9])
    ys = [cells[(t, "published")] for t in DMC9]
    if any(len(y) < ctx.min_seeds for y in ys):
        raise cl.NotEnoughData(f"the published DrQ-v2 curves do not cover {ctx.budget_text()} on every task")
    return cl.published_gain_rule(ctx, stacked(cells, [(t, "TACO") for t in DMC9]), ys)


def _judge_offline_average(ctx: Context, cells: Cells) -> tuple[str, str]:
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    cl.require(ctx, means_table(cells), [(t, d, m) for t, d in pairs for m in cl.OFFLINE_AVERAGED])
    return cl.offline_average_rule(ctx, {m: stacked(cells, [(t, d, m) for t, d in pairs])
                                         for m in cl.OFFLINE_AVERAGED})


def _judge_seeds(ctx: Context, cells: Cells) -> tuple[str, str]:
    return cl.seed_robustness_rule(ctx, {k: cell_spread(v) for k, v in cells.items() if len(v)})


def _judge_manipulator(ctx: Context, cells: Cells) -> tuple[str, str]:
    return cl.manipulator_rule(ctx, {k[0]: {"runs": len(v), "solved": int(v.sum()), "last_frame": float(ctx.budget)}
                                     for k, v in cells.items()})


def _on_table(rule: Callable[[Context, dict], tuple[str, str]]) -> Callable[[Context, Cells], tuple[str, str]]:
    return lambda ctx, cells: rule(ctx, means_table(cells))


# ---------------------------------------------------------------- the same verdicts, every draw at once
def _sims(draws: Draws) -> int:
    return next(iter(draws.values())).shape[0]


def _enough(ctx: Context, draws: Draws, key: Key) -> bool:
    """analysis.claims.get's test of a cell (its seeds are the same number in every draw)."""
    return key in draws and draws[key].shape[1] > 0 and draws[key].shape[1] >= ctx.min_seeds


def _near(a: np.ndarray, b: np.ndarray | float) -> np.ndarray:
    """Where ``a`` and ``b`` are within :data:`TIE` of each other (relative)."""
    return np.abs(a - b) <= TIE * (1.0 + np.abs(a) + np.abs(b))


def _verdicts(sims: int, supported: np.ndarray | bool, otherwise: str, unsure: np.ndarray | bool) -> np.ndarray:
    out = np.where(np.broadcast_to(supported, (sims,)), cl.SUPPORTED, otherwise).astype(object)
    out[np.broadcast_to(unsure, (sims,))] = ""
    return out


def _all(sims: int, verdict: str) -> np.ndarray:
    return np.full(sims, verdict, dtype=object)


def _stacked_draws(draws: Draws, keys: Sequence[Key]) -> np.ndarray:
    """:func:`stacked` of every draw: (draws x seeds x cells)."""
    k = min(draws[key].shape[1] for key in keys)
    return np.stack([draws[key][:, :k] for key in keys], axis=2)


def universal_batch(pairs: Callable[[Context], Sequence[tuple[Key, Key, str]]]) -> BatchJudge:
    """analysis.claims.universal over a means table, every draw at once: refuted where a pair present fails,
    else not enough data where one is missing, else supported."""

    def judge(ctx: Context, draws: Draws) -> np.ndarray:
        sims = _sims(draws)
        fail, unsure, missing = np.zeros(sims, bool), np.zeros(sims, bool), False
        for a, b, _ in pairs(ctx):
            if not (_enough(ctx, draws, a) and _enough(ctx, draws, b)):
                missing = True
                continue
            va, vb = draws[a].mean(axis=1), draws[b].mean(axis=1)
            fail |= ~(va > vb)
            unsure |= _near(va, vb)
        out = np.where(fail, cl.REFUTED, cl.NO_DATA if missing else cl.SUPPORTED).astype(object)
        out[unsure] = ""
        return out

    return judge


def _gain_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """:func:`_judge_gain` (analysis.claims.avg_gain_rule) in every draw."""
    sims = _sims(draws)
    taco, drq = [(t, "TACO") for t in DMC9], [(t, "DrQ-v2") for t in DMC9]
    if not all(_enough(ctx, draws, k) for k in taco + drq):
        return _all(sims, cl.NO_DATA)
    r = bs.RATIO_OF_MEANS.vector(_stacked_draws(draws, taco), _stacked_draws(draws, drq))[:, 0]
    return _verdicts(sims, r >= cl.GAIN_BAR, cl.REFUTED, _near(r, cl.GAIN_BAR))


def _published_gain_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """:func:`_judge_published_gain` (analysis.claims.published_gain_rule) in every draw."""
    sims = _sims(draws)
    taco = [(t, "TACO") for t in DMC9]
    if not all(_enough(ctx, draws, k) for k in taco):
        return _all(sims, cl.NO_DATA)
    ys = [np.ascontiguousarray(draws[(t, "published")], dtype=float) for t in DMC9]
    if any(y.shape[1] < ctx.min_seeds for y in ys):
        return _all(sims, cl.NO_DATA)
    r = bs.RATIO_TO_TASK_MEANS.vector(_stacked_draws(draws, taco), *(y[:, :, None] for y in ys))[:, 0]
    return _verdicts(sims, r >= cl.GAIN_BAR, cl.REFUTED, _near(r, cl.GAIN_BAR))


def _model_based_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.beats_model_based_rule in every draw (a baseline without cells: Table 1's value)."""
    sims = _sims(draws)
    if not all(_enough(ctx, draws, (t, "TACO")) for t in DMC9):
        return _all(sims, cl.NO_DATA)
    wins, unsure = np.zeros(sims, int), np.zeros(sims, bool)
    for t in DMC9:
        base = []
        for m in cl.MODEL_BASED:
            if _enough(ctx, draws, (t, m)):
                base.append(draws[(t, m)].mean(axis=1))
            else:
                printed = ctx.paper.online_value(t, m)
                assert printed is not None  # Table 1 has both baselines on every DMC task
                base.append(np.full(sims, float(printed[0])))
        best = np.max(np.stack(base), axis=0)
        taco = draws[(t, "TACO")].mean(axis=1)
        wins += taco > best
        unsure |= _near(taco, best)
    return _verdicts(sims, wins >= 6, cl.REFUTED, unsure)


def _seeds_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.seed_robustness_rule on every draw's cell spreads (analysis.robustness.cell_spread)."""
    sims = _sims(draws)
    got = {k: v for k, v in draws.items() if v.shape[1] > 0 and v.shape[1] >= ctx.min_seeds}
    tasks = [t for t in DMC9 if (t, "TACO") in got and (t, "DrQ-v2") in got]
    if len(tasks) < 9:
        return _all(sims, cl.NO_DATA)
    less, broken, unsure = np.zeros(sims, int), np.zeros(sims, int), np.zeros(sims, bool)
    for t in tasks:
        a, b = got[(t, "TACO")], got[(t, "DrQ-v2")]
        sa = a.std(ddof=1, axis=1) if a.shape[1] > 1 else np.full(sims, math.nan)
        sb = b.std(ddof=1, axis=1) if b.shape[1] > 1 else np.full(sims, math.nan)
        less += sa < sb
        unsure |= _near(sa, sb)
    for k, v in got.items():
        if k[1] != "DrQ-v2":
            continue
        med = np.median(v, axis=1)
        half = BROKEN_FRACTION * med
        broken += np.where(med > 0, (v < half[:, None]).sum(axis=1), 0)
        unsure |= _near(med, 0.0) | _near(v, half[:, None]).any(axis=1)
    return _verdicts(sims, (less >= 7) & (broken >= 1), cl.REFUTED, unsure)


def _manipulator_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.manipulator_rule on every draw's solved counts (values 0 or 1: exact sums)."""
    sims = _sims(draws)
    runs = {k[0]: v.shape[1] for k, v in draws.items()}
    solved = {k[0]: v.sum(axis=1) for k, v in draws.items()}
    drq_solves = solved["DrQ-v2"] > 0 if "DrQ-v2" in solved else np.zeros(sims, bool)
    if "TACO" not in runs or "DrQ-v2" not in runs or min(runs.values()) < ctx.min_seeds:
        out = _all(sims, cl.NO_DATA)
    else:
        # every cell's last frame is the budget in the simulation: short of a third of TACO's seeds is refuted
        out = np.where(solved["TACO"] / runs["TACO"] >= 1 / 3, cl.SUPPORTED, cl.REFUTED).astype(object)
    out[drq_solves] = cl.REFUTED
    return out


def _offline_average_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.offline_average_rule in every draw: each printed average inside its method's bootstrap CI
    (the same CIs: the bootstrap indices depend only on the shapes and the random state, so they are drawn once)."""
    sims = _sims(draws)
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    keys = [(t, d, m) for t, d in pairs for m in cl.OFFLINE_AVERAGED]
    if not all(_enough(ctx, draws, k) for k in keys):
        return _all(sims, cl.NO_DATA)
    ok = np.ones(sims, bool)
    for m, p in cl.offline_printed(ctx).items():
        mats = _stacked_draws(draws, [(t, d, m) for t, d in pairs])
        cis = bs.same_shape_intervals(bs.MEAN, [[mats[i]] for i in range(sims)], ctx.reps, ctx.seed)
        lo, hi = np.array([c[0][0] for c in cis]), np.array([c[1][0] for c in cis])
        ok &= (lo <= p) & (p <= hi)
    return _verdicts(sims, ok, cl.REFUTED, False)


def _online_observed(ctx: Context) -> Cells:
    return observed_cells(cl.online_rows(ctx), ["task", "method"])


def _offline_observed(ctx: Context) -> Cells:
    return observed_cells(offline_runs(cl.offline_scores(ctx), ctx.experiment_map), ["task", "dataset", "method"],
                          "normalized")


def _seeds_observed(ctx: Context) -> Cells:
    df = select.online_main(ctx.scores, ctx.experiment_map)
    return observed_cells(df[df["label"].isin(["TACO", "DrQ-v2"])] if not df.empty else df, ["task", "label"])


def _repr_observed(ctx: Context) -> Cells:
    return observed_cells(cl.labelled(select.repr_objectives(ctx.scores, ctx.experiment_map)), ["task", "method"])


def simulated_claims(ctx: Context, budgets: Mapping[str, ClaimBudget] | None = None) -> list[SimClaim]:
    """Every claim this module can simulate, with its cells' sources from the paper (``ctx.paper``) and the
    published DrQ-v2 curves (``ctx.published``)."""
    budgets = budgets or load_budgets()
    b1 = float(budgets["online_beats_drqv2_all"].budget or 0)

    def taco(t: str) -> CellSource:
        v = ctx.paper.online_value(t, "TACO")
        assert v is not None, t
        return paper_normal((t, "TACO"), v[0], v[1], "Table 1")

    online = [taco(t) for t in DMC9] + [drqv2_cell(ctx, t, b1, (t, "DrQ-v2")) for t in DMC9]
    fixed_pub = [CellSource((t, "published"), "fixed", math.nan, math.nan,
                            values=tuple(float(v) for v in published_values(ctx.published, t, b1)),
                            source=f"published DrQ-v2 curves at {frames_text(b1)}, as published") for t in DMC9]
    repr_cells = [taco(t) for t in cl.REPR_TASKS]
    for t in cl.REPR_TASKS:
        for m in ctx.paper.repr_others:
            v = ctx.paper.repr_value(t, m)
            if v is not None:
                repr_cells.append(paper_normal((t, m), v[0], v[1], "Table 2"))
    off = ctx.paper.offline
    offline_cells = [paper_normal((r.task, r.dataset, r.method), float(r.normalized_mean), float(r.normalized_std),
                                  "Table 3 (normalised)", *NORMALIZED_RANGE)
                     for r in off.itertuples(index=False)
                     if r.task in OFFLINE_TASKS and r.dataset in DatasetKind.values() and pd.notna(r.normalized_mean)]
    gain_cells = [c for c in offline_cells if c.key[2] in ("TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL")]
    manip = [CellSource(("TACO",), "bernoulli", 3 / 6, math.nan, source="appendix G: 3 of 6 seeds solve"),
             CellSource(("DrQ-v2",), "bernoulli", 0.0, math.nan, source="appendix G: 0 of 6 seeds solve")]
    offline_note = ("the rule compares returns; the cells are Table 3's normalised scores (100 x return / the "
                    "reference return, increasing in the return), so every comparison agrees")
    out = [
        SimClaim("online_avg_gain", budgets["online_avg_gain"], online, _judge_gain, _online_observed, DMC9,
                 batch=_gain_batch),
        SimClaim(cl.PUBLISHED_GAIN_ID, budgets["online_avg_gain"], [taco(t) for t in DMC9] + fixed_pub,
                 _judge_published_gain, _online_observed, DMC9,
                 notes=["DrQ-v2 is the published curves as published (fixed data, as `repro claims` reads them)"],
                 batch=_published_gain_batch),
        SimClaim("online_beats_drqv2_all", budgets["online_beats_drqv2_all"], online, _on_table(cl.beats_drqv2_rule),
                 _online_observed, DMC9, batch=universal_batch(lambda c: cl.beats_drqv2_pairs())),
        SimClaim("online_beats_model_based", budgets["online_beats_model_based"], [taco(t) for t in DMC9],
                 _on_table(cl.beats_model_based_rule), _online_observed, DMC9,
                 notes=["DreamerV3 and TD-MPC are Table 1's printed means (not rerun by any sweep), as the rule "
                        "reads them"], batch=_model_based_batch),
        SimClaim("vs_repr_objectives", budgets["vs_repr_objectives"], repr_cells, _on_table(cl.vs_repr_rule),
                 _repr_observed, cl.REPR_TASKS, batch=universal_batch(cl.vs_repr_pairs)),
        SimClaim("offline_gain", budgets["offline_gain"], gain_cells, _on_table(cl.offline_gain_rule),
                 _offline_observed, OFFLINE_TASKS, notes=[offline_note],
                 batch=universal_batch(lambda c: cl.offline_gain_pairs())),
        SimClaim("offline_average", budgets["offline_average"], gain_cells, _judge_offline_average, _offline_observed,
                 OFFLINE_TASKS, sims=CI_SIMS, reps=CI_REPS,
                 notes=[f"its verdict reads a bootstrap CI: rliable's bootstrap runs in every draw ({CI_REPS} "
                        f"repetitions instead of {ctx.reps:,}; {CI_SIMS} draws)"], batch=_offline_average_batch),
        SimClaim("seed_robustness", budgets["seed_robustness"], online, _judge_seeds, _seeds_observed, DMC9,
                 notes=["a broken seed is one below half its cell's median: normal cells almost never have one, so "
                        "DrQ-v2's published values carry the claim's second half"], batch=_seeds_batch),
        SimClaim("manipulator", budgets["manipulator"], manip, _judge_manipulator, None, ("manipulator_bring_ball",),
                 notes=["DrQ-v2's 0 of 6 taken as a solve probability of 0 (its 95% upper bound is 39%): optimistic",
                        "not conditioned on runs (the rule reads learning curves)"], batch=_manipulator_batch),
    ]
    return out


# ---------------------------------------------------------------- simulation
class _MemoPaper(PaperData):
    """The paper's tables with memoised cell lookups: a rule reads the same printed baselines in every draw."""

    def __init__(self, paper: PaperData) -> None:
        super().__init__(paper.root)
        self._online: dict[tuple[str, str], tuple[float, float] | None] = {}
        self._repr: dict[tuple[str, str], tuple[float, float] | None] = {}

    def online_value(self, task: str, method: str) -> tuple[float, float] | None:
        if (task, method) not in self._online:
            self._online[(task, method)] = super().online_value(task, method)
        return self._online[(task, method)]

    def repr_value(self, task: str, method: str) -> tuple[float, float] | None:
        if (task, method) not in self._repr:
            self._repr[(task, method)] = super().repr_value(task, method)
        return self._repr[(task, method)]


def sim_context(ctx: Context, claim: SimClaim, min_seeds: int = 1) -> Context:
    """The context a rule sees in the simulation: the claim's budget and seed minimum, no runs, no CI unless
    the verdict reads one (``claim.reps``)."""
    empty = Results(Path("."), pd.DataFrame(), pd.DataFrame())
    budget = claim.spec.budget if claim.spec.budget is not None else ctx.budget
    return Context(results=empty, paper=_MemoPaper(ctx.paper), budget=budget, reps=claim.reps, seed=ctx.seed,
                   min_seeds=max(claim.spec.min_seeds, min_seeds), cache={})


@dataclass(frozen=True)
class Power:
    """P(supported) and P(refuted) over ``sims`` draws at ``seeds`` per cell, with the Monte-Carlo error."""

    seeds: int
    supported: float
    refuted: float
    sims: int

    @property
    def error(self) -> float:
        """The Monte-Carlo standard error of ``supported``."""
        return math.sqrt(self.supported * (1 - self.supported) / self.sims)

    def text(self) -> str:
        return f"{self.supported:.2f} ± {self.error:.2f}"


def _rng(seed: int, claim_id: str, seeds: int) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32(claim_id.encode()), seeds])


def simulate(ctx: Context, claim: SimClaim, seeds: int, sims: int = DEFAULT_SIMS, seed: int = 0,
             observed: Cells | None = None, min_seeds: int = 1) -> Power:
    """The claim's verdicts over ``sims`` draws with ``seeds`` per cell (the ``observed`` values of a cell kept,
    only its missing seeds drawn); computed once per claim and arguments (``claim.memo``)."""
    key = (id(ctx.paper), ctx.budget, seeds, sims, seed, min_seeds,
           tuple(sorted((k, np.asarray(v, dtype=float).tobytes()) for k, v in (observed or {}).items())))
    if key not in claim.memo:
        claim.memo[key] = _simulate(ctx, claim, seeds, sims, seed, observed, min_seeds)
    return claim.memo[key]


def _simulate(ctx: Context, claim: SimClaim, seeds: int, sims: int, seed: int, observed: Cells | None,
              min_seeds: int) -> Power:
    sims = min(claim.sims, sims) if claim.sims else sims
    rng = _rng(seed, claim.id, seeds)
    sctx = sim_context(ctx, claim, min_seeds)
    arrays: dict[Key, np.ndarray] = {}
    for cell in claim.cells:
        have = np.asarray((observed or {}).get(cell.key, np.empty(0)), dtype=float)
        new = cell.draw(rng, sims, max(0, seeds - len(have)) if cell.kind != "fixed" else 0)
        arrays[cell.key] = np.concatenate([np.broadcast_to(have, (sims, len(have))), new], axis=1) \
            if cell.kind != "fixed" else new
    counts = {cl.SUPPORTED: 0, cl.REFUTED: 0, cl.NO_DATA: 0}
    batch = claim.batch(sctx, arrays) if claim.batch is not None and arrays else None
    for i in range(sims):
        verdict = batch[i] if batch is not None else ""
        if not verdict:
            verdict = judge_draw(sctx, claim, {k: a[i] for k, a in arrays.items()})
        counts[verdict] += 1
    return Power(seeds, counts[cl.SUPPORTED] / sims, counts[cl.REFUTED] / sims, sims)


def judge_draw(sctx: Context, claim: SimClaim, cells: Cells) -> str:
    """The claim's verdict on one draw, by its rule."""
    try:
        verdict, _ = claim.judge(sctx, cells)
    except cl.NotEnoughData:
        verdict = cl.NO_DATA
    return verdict


def seeds_for(ctx: Context, claim: SimClaim, target: float = TARGET, sims: int = DEFAULT_SIMS, seed: int = 0,
              max_seeds: int = DEFAULT_MAX_SEEDS, observed: Cells | None = None,
              min_seeds: int = 1) -> tuple[int | None, Power]:
    """The fewest seeds per cell (from the claim's minimum up to ``max_seeds``) with simulated power >= ``target``,
    and the power there; (None, the power at ``max_seeds``) if none reaches it."""
    lo = max(claim.spec.min_seeds, min_seeds, max((len(v) for v in (observed or {}).values()), default=0))

    def power(n: int) -> Power:
        return simulate(ctx, claim, n, sims, seed, observed, min_seeds)

    first = power(lo)
    if first.supported >= target:
        return lo, first
    fail, n = lo, lo
    while True:
        n = min(2 * n, max_seeds)
        p = power(n)
        if p.supported >= target:
            break
        if n >= max_seeds:
            return None, p
        fail = n
    best = (n, p)
    lo_n, hi_n = fail, n
    while hi_n - lo_n > 1:
        mid = (lo_n + hi_n) // 2
        pm = power(mid)
        if pm.supported >= target:
            hi_n, best = mid, (mid, pm)
        else:
            lo_n = mid
    return best


# ---------------------------------------------------------------- tables
@dataclass
class PowerRow:
    """One claim of the power table: at the claim's seed minimum and at the paper's seed count, the seeds for
    80%, and (with runs) the power given the seeds done."""

    id: str
    simulated: bool
    rule: str
    min_seeds: int
    paper_seeds: int
    at_min: Power | None = None
    at_paper: Power | None = None
    seeds_80: int | None = None
    at_80: Power | None = None
    reason: str = ""
    notes: list[str] = field(default_factory=list)
    done_seeds: int = 0  # fewest seeds done in a cell of the claim (with runs)
    now: Power | None = None  # P(supported) at the claim's minimum given the seeds done
    more_80: int | None = None  # more seeds per cell (beyond the most done in a cell) for 80% given those done
    verdict: str = ""  # `repro claims` verdict and evidence now (with runs)
    evidence: str = ""
    cells: list[CellSource] = field(default_factory=list)
    tasks: tuple[str, ...] = ()  # the tasks of the claim's runs
    experiments: tuple[str, ...] = ()  # the experiments (sweeps) the claim reads


def power_rows(ctx: Context, sims: int = DEFAULT_SIMS, max_seeds: int = DEFAULT_MAX_SEEDS,
               verdicts: Sequence[cl.Verdict] | None = None, conditioned: bool = False,
               bootstrap_claims: bool = True) -> list[PowerRow]:
    """One row per claim of claims.csv (and the published-curves reading of online_avg_gain), in that order.
    ``conditioned``: also the power given the user's runs in ``ctx`` (and their ``verdicts``);
    ``bootstrap_claims`` False: leave out the claims whose rule runs a bootstrap in every draw (the report)."""
    budgets = load_budgets()
    sim = {c.id: c for c in simulated_claims(ctx, budgets)}
    ids = [i for cid in ctx.paper.claims["id"] for i in ([cid, cl.PUBLISHED_GAIN_ID] if cid == "online_avg_gain"
                                                          else [cid])]
    by_verdict = {v.id: v for v in verdicts or []}
    rows = []
    for cid in ids:
        spec = budgets.get("online_avg_gain" if cid == cl.PUBLISHED_GAIN_ID else cid)
        rule = cl.PUBLISHED_GAIN_RULE if cid == cl.PUBLISHED_GAIN_ID else cl.CHECKS.get(cid, (None, ""))[1]
        if spec is None:
            rows.append(PowerRow(cid, False, rule, 0, 0, reason="no budget in claim_budgets.csv"))
            continue
        seeds = max(spec.min_seeds, ctx.min_seeds)
        row = PowerRow(cid, cid in sim, rule, seeds, spec.paper_seeds, experiments=spec.experiments)
        if cid in by_verdict:
            row.verdict, row.evidence = by_verdict[cid].shown, by_verdict[cid].evidence
        if cid not in sim:
            row.reason = NOT_SIMULATED.get(cid, "no simulation for this claim")
            rows.append(row)
            continue
        c = sim[cid]
        if c.reps and not bootstrap_claims:
            row.simulated, row.reason = False, ("its rule runs a bootstrap in every draw: simulated by `repro plan "
                                                "--claims`, not here")
            rows.append(row)
            continue
        row.cells, row.notes, row.tasks = c.cells, c.notes, c.tasks
        row.at_min = simulate(ctx, c, seeds, sims, ctx.seed, min_seeds=ctx.min_seeds)
        row.at_paper = simulate(ctx, c, max(spec.paper_seeds, seeds), sims, ctx.seed, min_seeds=ctx.min_seeds)
        row.seeds_80, row.at_80 = seeds_for(ctx, c, TARGET, sims, ctx.seed, max_seeds, min_seeds=ctx.min_seeds)
        if conditioned and c.observed is not None:
            condition_row(ctx, c, row, sims, max_seeds)
        rows.append(row)
    return rows


def condition_row(ctx: Context, claim: SimClaim, row: PowerRow, sims: int, max_seeds: int) -> None:
    """Fill the conditioned columns of ``row`` from the user's runs at the claim's budget."""
    cctx = cl._claim_context(ctx, claim.spec, claim.spec.budget, below=False)
    observed = {k: v for k, v in claim.observed(cctx).items() if k in {c.key for c in claim.cells}} \
        if claim.observed is not None else {}
    drawn = [c.key for c in claim.cells if c.kind != "fixed"]
    row.done_seeds = min((len(observed.get(k, ())) for k in drawn), default=0)
    most = max((len(v) for v in observed.values()), default=0)
    row.now = simulate(ctx, claim, max(row.min_seeds, most), sims, ctx.seed, observed, ctx.min_seeds)
    n80, _ = seeds_for(ctx, claim, TARGET, sims, ctx.seed, max_seeds, observed, ctx.min_seeds)
    row.more_80 = None if n80 is None else n80 - row.done_seeds


def _seeds_text(row: PowerRow, max_seeds: int) -> str:
    if not row.simulated:
        return ""
    return str(row.seeds_80) if row.seeds_80 is not None else f"> {max_seeds}"


def power_frames(rows: Sequence[PowerRow], max_seeds: int = DEFAULT_MAX_SEEDS,
                 cost: Callable[[str, int], str] | None = None,
                 conditioned: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of the power table; ``cost(claim, seeds)`` says what those seeds cost."""
    raw = pd.DataFrame([{
        "id": r.id, "simulated": r.simulated, "min_seeds": r.min_seeds, "paper_seeds": r.paper_seeds,
        "power_at_min": r.at_min.supported if r.at_min else math.nan,
        "mc_error_at_min": r.at_min.error if r.at_min else math.nan,
        "power_at_paper_seeds": r.at_paper.supported if r.at_paper else math.nan,
        "mc_error_at_paper_seeds": r.at_paper.error if r.at_paper else math.nan,
        "refuted_at_paper_seeds": r.at_paper.refuted if r.at_paper else math.nan,
        "sims": r.at_min.sims if r.at_min else 0, "seeds_for_80": r.seeds_80,
        "power_at_seeds_for_80": r.at_80.supported if r.at_80 else math.nan,
        "cost_of_seeds_for_80": cost(r.id, r.seeds_80) if cost and r.seeds_80 else "",
        "verdict_now": r.verdict, "evidence_now": r.evidence, "seeds_done": r.done_seeds,
        "power_given_done": r.now.supported if r.now else math.nan, "more_seeds_for_80": r.more_80,
        "not_simulated_because": r.reason, "notes": "; ".join(r.notes), "rule": r.rule,
    } for r in rows])
    display = pd.DataFrame({
        "Claim": [r.id for r in rows],
        "Seeds (min / paper)": [f"{r.min_seeds} / {r.paper_seeds}" if r.min_seeds else "" for r in rows],
        "P(supported) at min": [r.at_min.text() if r.at_min else "not simulated" for r in rows],
        "at paper's seeds": [r.at_paper.text() if r.at_paper else "" for r in rows],
        "Seeds for 80%": [_seeds_text(r, max_seeds) for r in rows],
        "Cost of those seeds": [cost(r.id, r.seeds_80) if cost and r.seeds_80 else "" for r in rows],
    })
    if conditioned:
        display["Now"] = [r.verdict for r in rows]
        display["Seeds done"] = [str(r.done_seeds) if r.simulated else "" for r in rows]
        display["P(supported) given done"] = [fmt_num(r.now.supported, 2) if r.now else "" for r in rows]
        display["More seeds for 80%"] = [("" if not r.now else str(r.more_80) if r.more_80 is not None
                                          else f"> {max_seeds - r.done_seeds}") for r in rows]
    display["Why not simulated / notes"] = [r.reason or "; ".join(r.notes) for r in rows]
    return raw, display


def cells_frame(rows: Sequence[PowerRow]) -> pd.DataFrame:
    """One row per simulated cell: claim, cell, the truth assumed, its source and its distribution."""
    return pd.DataFrame([{"Claim": r.id, "Cell": "/".join(str(p) for p in c.key),
                          "Mean": fmt_num(c.mean) if c.kind != "fixed" else fmt_num(np.mean(c.values)),
                          "Std": fmt_num(c.std), "Source": c.source, "Distribution": c.describe()}
                         for r in rows for c in r.cells], columns=["Claim", "Cell", "Mean", "Std", "Source",
                                                                   "Distribution"])


def power_notes(sims: int, seed: int, max_seeds: int) -> list[str]:
    """The assumptions stated under the power table."""
    return [
        "P(supported): the probability that the claim's rule, applied as `repro claims` applies it (same statistic, "
        "same seed minimum, analysis/claims.py), says 'supported' if the paper's numbers are the truth; ± is the "
        f"Monte-Carlo standard error over {sims:,} draws (fewer where stated), random state {seed}.",
        "Cells: DrQ-v2 on a DMC task draws the DrQ-v2 authors' published per-seed values at the claim's budget "
        "(interpolated between evaluations), shifted to Table 1's mean; every other cell is normal with the "
        "paper's mean and std, truncated at the return range; each cell's source: plan_power_cells.",
        "These rules compare means with no significance threshold: two equal cells give 'supported' about half "
        "the time, so a high P(supported) says the paper's gap is large against the seed noise, not that a "
        "test controls false positives.",
        f"Seeds for 80%: the fewest seeds per cell (from the claim's minimum, at most {max_seeds}) with simulated "
        "P(supported) >= 0.8, found by doubling then bisection.",
    ]


def write_power(out_dir: Path, rows: Sequence[PowerRow], sims: int, seed: int,
                max_seeds: int = DEFAULT_MAX_SEEDS, cost: Callable[[str, int], str] | None = None,
                conditioned: bool = False, extra_notes: Sequence[str] = ()) -> tuple[TableOutput, TableOutput]:
    """Write ``plan_power.csv/.md/.tex`` and ``plan_power_cells.csv/.md/.tex``."""
    raw, display = power_frames(rows, max_seeds, cost, conditioned)
    n_sim = sum(r.simulated for r in rows)
    caption = (f"Statistical power of each claim if the paper's numbers are the truth ({n_sim} of {len(rows)} "
               "claims simulated through their own rules)"
               + ("; conditioned on the runs done" if conditioned else "") + ".")
    notes = power_notes(sims, seed, max_seeds) + list(extra_notes)
    if conditioned:
        notes.append("Given done: the values of the seeds already run (that reached the claim's budget) are kept in "
                     "each cell, only the missing seeds are drawn; More seeds for 80%: per cell, beyond the fewest "
                     "done in a cell.")
    table = write_table(out_dir, "plan_power", raw, caption, display, notes)
    cells = cells_frame(rows)
    cells_table = write_table(out_dir, "plan_power_cells", cells,
                              "The truth assumed in every simulated cell, with its source and distribution.")
    return table, cells_table


def next_runs_paragraph(rows: Sequence[PowerRow], max_seeds: int = DEFAULT_MAX_SEEDS) -> str:
    """The report's "what to run next": per simulated claim still short of a verdict or below 80%, the seeds."""
    lines = []
    for r in rows:
        if not r.simulated or r.now is None:
            continue
        if r.more_80 is None:
            lines.append(f"- `{r.id}` ({r.verdict or 'no verdict'}): P(supported) {r.now.supported:.2f} given the "
                         f"{r.done_seeds} seed(s) done; even {max_seeds} seeds per cell would not reach 80% if the "
                         "paper's numbers are the truth.")
        elif r.more_80 > 0:
            lines.append(f"- `{r.id}` ({r.verdict or 'no verdict'}): P(supported) {r.now.supported:.2f} given the "
                         f"{r.done_seeds} seed(s) done; {r.more_80} more seed(s) per cell reach 80%.")
    if not any(r.now is not None for r in rows):
        return ("What to run next: no runs yet. If the paper's numbers are the truth, column 'Seeds for 80%' gives "
                "the seeds per cell that each simulated claim needs.")
    if not lines:
        return "Every simulated claim already reaches 80% power with the seeds done."
    return "What to run next (if the paper's numbers are the truth):\n\n" + "\n".join(lines)
