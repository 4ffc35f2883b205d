"""What a claim's rule is written with: cells over a leading draws axis (:data:`Draws`), judged all at once.

A simulated claim's rule is one function of its cells as :data:`Draws` (cell -> (draws, seeds) values) and of the
numbers it compares with (the paper's, its seed minimum and budget, the bootstrap of a CI); it returns a
:class:`~analysis.claims.core.Judgement`, the verdict of every draw and the evidence of draw 0. `repro claims` calls
it on the user's runs as one draw (:func:`one_draw`, :func:`judged`); the power simulation (analysis/power.py) on all
its draws at once, so there is one rule and no second copy of it. Every draw has the same seeds per cell, so whether
a cell has enough of them is decided once, before any value is read (:func:`require_cells`, :func:`enough`), and
every statistic reduces over the seeds (the last axes), draw by draw, the same way for one draw as for many.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from analysis.cells import Cells, Key
from analysis.claims.core import NO_DATA, REFUTED, SUPPORTED, Check, Draws, Judge, Judgement, too_few_seeds, vs_text
from analysis.context import Context

Pair = tuple[Key, Key, str]  # 'A > B': (A's cell, B's cell, the comparison's name in the evidence)


def one_draw(cells: Cells) -> Draws:
    """The cells of the runs (cell -> values over its seeds) as the one draw a rule reads."""
    return {k: np.asarray(v, dtype=float)[None, :] for k, v in cells.items()}


def claim_cells(ctx: Context, cells: Callable[[Context], Cells]) -> Cells:
    """``cells(ctx)``, the cells of the runs a claim reads in its context ``ctx`` (analysis.claims.claim_context),
    read once per context: kept in ``ctx.cache``, which the claims' contexts share, so that the power conditioned on
    the runs (analysis/power.py) reuses the cells `repro claims` read instead of reading the runs again. The entry
    holds ``ctx`` itself, so an entry is found only by the context that read it."""
    key = ("claim-cells", cells, id(ctx))
    kept = ctx.cache.get(key)
    if kept is None or kept[0] is not ctx:
        kept = ctx.cache[key] = (ctx, read_cells(ctx, cells))
    return kept[1]


def read_cells(ctx: Context, cells: Callable[[Context], Cells]) -> Cells:
    """``cells(ctx)`` read from the runs (what :func:`claim_cells` keeps)."""
    return cells(ctx)


def judged(cells: Callable[[Context], Cells], judge: Judge) -> Check:
    """A simulated claim's check on the runs: its rule (``judge``) on the cells of the runs (``cells``, read once per
    claim context: :func:`claim_cells`), one draw."""
    return lambda ctx: judge(ctx, one_draw(claim_cells(ctx, cells))).first


def n_draws(draws: Draws) -> int:
    """How many draws ``draws`` holds (one when it has no cell)."""
    return next(iter(draws.values())).shape[0] if draws else 1


def enough(draws: Draws, key: Key, min_seeds: int) -> bool:
    """Whether cell ``key`` has at least one seed and at least ``min_seeds`` (the same in every draw)."""
    return key in draws and draws[key].shape[1] > 0 and draws[key].shape[1] >= min_seeds


def require_cells(draws: Draws, keys: Sequence[Key], min_seeds: int, budget: str) -> None:
    """analysis.claims.core.too_few_seeds of the cells of ``keys`` with fewer than ``min_seeds`` seeds that reached
    ``budget`` (in words)."""
    missing = [k for k in keys if not enough(draws, k, min_seeds)]
    if missing:
        raise too_few_seeds(missing, min_seeds, budget)


def stacked(draws: Draws, keys: Sequence[Key]) -> np.ndarray:
    """A (draws, seeds, cells) array of ``keys``' cells, each cut to the fewest seeds among them: in every draw the
    (seeds x cells) matrix analysis.stats.score_matrix builds from runs."""
    k = min(draws[key].shape[1] for key in keys)
    return np.ascontiguousarray(np.stack([draws[key][:, :k] for key in keys], axis=2), dtype=float)


def verdicts(supported: np.ndarray, otherwise: str = REFUTED) -> np.ndarray:
    """Every draw's verdict: supported where ``supported``, else ``otherwise``."""
    return np.where(supported, SUPPORTED, otherwise).astype(object)


def universal(draws: Draws, pairs: Sequence[Pair], min_seeds: int, budget: str) -> Judgement:
    """'A > B' for every pair, on the means over the seeds: in each draw refuted by any counterexample among the pairs
    whose cells both have ``min_seeds`` seeds, else not enough data where a pair lacks them, else supported."""
    sims = n_draws(draws)
    fail = np.zeros(sims, dtype=bool)
    lines, fails, missing = [], [], []
    for a, b, name in pairs:
        if not (enough(draws, a, min_seeds) and enough(draws, b, min_seeds)):
            missing.append(name)
            continue
        va, vb = draws[a].mean(axis=1), draws[b].mean(axis=1)
        lost = ~(va > vb)
        fail |= lost
        lines.append(f"{name}: {vs_text(va[0], vb[0], 1)}")
        if lost[0]:
            fails.append(name)
    evidence = "; ".join(lines)
    if fails:
        evidence = f"fails on {', '.join(fails)}. {evidence}"
    elif missing:
        evidence = (f"need >= {min_seeds} seeds that reached {budget} for: {', '.join(missing)}"
                    + (f". So far: {evidence}" if evidence else ""))
    return Judgement(np.where(fail, REFUTED, NO_DATA if missing else SUPPORTED).astype(object), evidence)
