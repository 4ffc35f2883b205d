"""The claims of the offline experiments (Table 3)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis import bootstrap as bs
from analysis.cells import Cells, means_table, observed_cells, stacked
from analysis.claims.core import NO_DATA, REFUTED, SUPPORTED, apart, means, require, universal
from analysis.claims.draws import Draws, _all, _enough, _near, _sims, _stacked_draws, _verdicts
from analysis.context import Context
from analysis.offline_tables import offline_runs
from analysis.paper import OFFLINE_TASKS
from analysis.stats import grand_mean_ci, score_matrix
from repro.config.schema import DatasetKind

OFFLINE_AVERAGED = ("TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL")  # offline_average's methods: the +-TACO pairs


def offline_printed(ctx: Context) -> dict[str, float]:
    """Table 3's printed average of each method of ``offline_average``, read from the packaged paper data
    (repro_data/paper/offline_average.csv), never repeated here."""
    avg = ctx.paper.offline_average
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


def _offline_table(ctx: Context, value: str = "score") -> tuple[dict, pd.DataFrame]:
    df = offline_runs(offline_scores(ctx), ctx.experiment_map)
    return means(df, ["task", "dataset", "method"], value), df


def _offline_gain(ctx: Context) -> tuple[str, str]:
    table, _ = _offline_table(ctx)
    return offline_gain_rule(ctx, table)


def offline_gain_pairs() -> list[tuple[tuple, tuple, str]]:
    """offline_gain's comparisons: X+TACO against X per task/dataset pair, X in TD3+BC and CQL."""
    return [((t, d, f"{x}+TACO"), (t, d, x), f"{t}/{d} {x}") for t in OFFLINE_TASKS
            for d in DatasetKind.values() for x in ("TD3+BC", "CQL")]


def offline_gain_rule(ctx: Context, table: dict[tuple, tuple[int, float]]) -> tuple[str, str]:
    """offline_gain on a (task, dataset, method) ``means`` table of returns."""
    return universal(ctx, table, offline_gain_pairs())


def _offline_average(ctx: Context) -> tuple[str, str]:
    table, df = _offline_table(ctx, "normalized")
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    require(ctx, table, [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED])
    matrices = {}
    for m in OFFLINE_AVERAGED:
        rows = df[(df["method"] == m) & df["reached"].astype(bool)]
        rows = rows.assign(task=rows["task"] + "/" + rows["dataset"])
        matrix, _ = score_matrix(rows, [f"{t}/{d}" for t, d in pairs], value="normalized")
        assert matrix is not None  # require() saw runs on every pair
        matrices[m] = matrix
    return offline_average_rule(ctx, matrices)


def offline_average_rule(ctx: Context, matrices: dict[str, np.ndarray]) -> tuple[str, str]:
    """offline_average on each printed method's (runs x 12 pairs) matrix of normalised scores: the verdict
    reads the bootstrap CI (``ctx.reps`` repetitions)."""
    ok, lines = True, []
    for m, p in offline_printed(ctx).items():
        mean, lo, hi = grand_mean_ci(matrices[m], ctx.reps, ctx.seed)
        inside = lo <= p <= hi
        ok &= inside
        mean_s, lo_s, hi_s, _ = apart([mean, lo, hi, float(p)], 1)
        lines.append(f"{m} {mean_s} [{lo_s}, {hi_s}] vs {p}{'' if inside else ' (outside)'}")
    return (SUPPORTED if ok else REFUTED), "; ".join(lines)


CI_REPS = 300  # bootstrap repetitions per simulated draw where the verdict reads a CI (offline_average)


CI_SIMS = 100  # simulated draws of such a claim (each runs four bootstraps)


def _judge_offline_average(ctx: Context, cells: Cells) -> tuple[str, str]:
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    require(ctx, means_table(cells), [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED])
    return offline_average_rule(ctx, {m: stacked(cells, [(t, d, m) for t, d in pairs]) for m in OFFLINE_AVERAGED})


def _offline_average_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.offline_average_rule in every draw: each printed average inside its method's bootstrap CI
    (the same bootstrap indices: they depend only on the shapes and the random state, so they are drawn once; the
    means as one product, :func:`analysis.bootstrap.mean_intervals_many`, so a draw whose bound lies within
    :data:`TIE` of the printed average is judged by the rule)."""
    sims = _sims(draws)
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    keys = [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED]
    if not all(_enough(ctx, draws, k) for k in keys):
        return _all(sims, NO_DATA)
    ok, unsure = np.ones(sims, bool), np.zeros(sims, bool)
    for m, p in offline_printed(ctx).items():
        lo, hi = bs.mean_intervals_many(_stacked_draws(draws, [(t, d, m) for t, d in pairs]), ctx.reps, ctx.seed)
        ok &= (lo <= p) & (p <= hi)
        unsure |= _near(lo, p) | _near(hi, p)
    return _verdicts(sims, ok, REFUTED, unsure)


def _offline_observed(ctx: Context) -> Cells:
    return observed_cells(offline_runs(offline_scores(ctx), ctx.experiment_map), ["task", "dataset", "method"],
                          "normalized")


_OFFLINE_NOTE = ("the rule compares returns; the cells are Table 3's normalised scores (100 x return / the reference "
                 "return, increasing in the return), so every comparison agrees")


