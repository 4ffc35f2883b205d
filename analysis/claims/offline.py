"""The claims of the offline experiments (Table 3): X+TACO against X on every task/dataset pair, and Table 3's printed
averages inside the reproduced averages' CIs. Both are simulated: each is its cells from the runs, its rule over a
leading draws axis (analysis/claims/draws.py) and a ``_judge_*`` giving the rule the numbers it reads."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from analysis.cells import Cells, CellSource, observed_cells, table3_cells
from analysis.claims.core import ClaimSpec, Draws, Judgement, Simulation, apart
from analysis.claims.draws import judged, n_draws, require_cells, stacked, universal, verdicts
from analysis.context import Context
from analysis.offline_tables import offline_runs
from analysis.paper import OFFLINE_TASKS, PaperData
from analysis.stats import grand_mean_cis
from repro.config.schema import DatasetKind

OFFLINE_AVERAGED = ("TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL")  # offline_average's methods: the +-TACO pairs
PAIRS = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]  # Table 3's 12 task/dataset pairs
CI_REPS = 300  # bootstrap repetitions per simulated draw where the verdict reads a CI (offline_average)
CI_SIMS = 100  # simulated draws of such a claim (each runs four bootstraps)


def offline_printed(paper: PaperData) -> dict[str, float]:
    """Table 3's printed average of each method of ``offline_average``, read from the packaged paper data
    (repro_data/paper/offline_average.csv), never repeated here."""
    avg = paper.offline_average
    printed = dict(zip(avg["method"], avg["average_normalized"].astype(float)))
    return {m: printed[m] for m in OFFLINE_AVERAGED}


def offline_scores(ctx: Context) -> pd.DataFrame:
    """Per-run scores for offline claims, at each run's own budget (its configured ``offline.updates``,
    analysis.scores.final_scores): ``reached`` when the run finished it. In an indicative reading every run
    with an evaluation counts at its latest evaluation, finished or not."""
    df = ctx.scores
    if df.empty:
        return df
    offline = df["dataset"].notna()
    reached = df["score"].notna() if ctx.below_budget else df["reached"].astype(bool)
    return df.assign(reached=(reached & offline).to_numpy(dtype=bool))


def _offline_cells(ctx: Context, value: str) -> Cells:
    """The offline runs' cells (task, dataset, method) of ``value`` (returns: "score"; "normalized")."""
    return observed_cells(offline_runs(offline_scores(ctx), ctx.experiment_map), ["task", "dataset", "method"], value)


def _returns(ctx: Context) -> Cells:
    return _offline_cells(ctx, "score")


def _normalized(ctx: Context) -> Cells:
    return _offline_cells(ctx, "normalized")


def offline_gain_pairs() -> list[tuple[tuple, tuple, str]]:
    """offline_gain's comparisons: X+TACO against X per task/dataset pair, X in TD3+BC and CQL."""
    return [((t, d, f"{x}+TACO"), (t, d, x), f"{t}/{d} {x}") for t, d in PAIRS for x in ("TD3+BC", "CQL")]


def offline_gain_rule(draws: Draws, *, min_seeds: int, budget: str) -> Judgement:
    """offline_gain: X+TACO's mean > X's on each pair (:func:`offline_gain_pairs`, :func:`universal`)."""
    return universal(draws, offline_gain_pairs(), min_seeds, budget)


def _judge_gain(ctx: Context, draws: Draws) -> Judgement:
    return offline_gain_rule(draws, min_seeds=ctx.min_seeds, budget=ctx.budget_text())


def offline_average_rule(draws: Draws, printed: Mapping[str, float], *, min_seeds: int, budget: str, reps: int,
                         seed: int) -> Judgement:
    """offline_average on (task, dataset, method) cells of normalised scores: in each draw, every method's printed
    average (``printed``) lies inside the rliable CI (``reps`` repetitions, random state ``seed``) of its mean over the
    12 pairs (each pair's cell cut to the fewest seeds among them, as analysis.stats.score_matrix cuts runs)."""
    keys = {m: [(t, d, m) for t, d in PAIRS] for m in printed}
    require_cells(draws, [(t, d, m) for t, d in PAIRS for m in printed], min_seeds, budget)
    ok, lines = np.ones(n_draws(draws), dtype=bool), []
    for m, p in printed.items():
        mean, lo, hi = grand_mean_cis(stacked(draws, keys[m]), reps, seed)
        inside = (lo <= p) & (p <= hi)
        ok &= inside
        mean_s, lo_s, hi_s, _ = apart([mean[0], lo[0], hi[0], float(p)], 1)
        lines.append(f"{m} {mean_s} [{lo_s}, {hi_s}] vs {p}{'' if inside[0] else ' (outside)'}")
    return Judgement(verdicts(ok), "; ".join(lines))


def _judge_average(ctx: Context, draws: Draws) -> Judgement:
    return offline_average_rule(draws, offline_printed(ctx.paper), min_seeds=ctx.min_seeds, budget=ctx.budget_text(),
                                reps=ctx.reps, seed=ctx.seed)


def _sources(ctx: Context, budget: float) -> list[CellSource]:
    return table3_cells(ctx, OFFLINE_AVERAGED)


_OFFLINE_NOTE = ("the rule compares returns; the cells are Table 3's normalised scores (100 x return / the reference "
                 "return, increasing in the return), so every comparison agrees")

SPECS: tuple[ClaimSpec, ...] = (
    ClaimSpec("offline_gain", judged(_returns, _judge_gain),
              "return of X+TACO > X for X in TD3+BC, CQL on each of the 12 task/dataset pairs",
              Simulation(_sources, _judge_gain, _normalized, OFFLINE_TASKS, notes=(_OFFLINE_NOTE,))),
    ClaimSpec("offline_average", judged(_normalized, _judge_average),
              "each printed average of Table 3's average row (TD3+BC+TACO, TD3+BC, CQL+TACO, CQL; "
              "repro_data/paper/offline_average.csv) lies in the 95% CI of the reproduced average normalised score "
              "over the 12 pairs",
              Simulation(_sources, _judge_average, _normalized, OFFLINE_TASKS, sims=CI_SIMS, reps=CI_REPS)),
)
