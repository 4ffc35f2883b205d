"""The claims' verdicts in every draw of the power simulation at once."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from analysis.cells import Cells, Key, means_table
from analysis.claims.core import NO_DATA, REFUTED, SUPPORTED, BatchJudge, Draws  # noqa: F401
from analysis.context import Context

TIE = 1e-9  # relative distance from a threshold under which a draw is judged by ``judge`` itself


def _sims(draws: Draws) -> int:
    return next(iter(draws.values())).shape[0]


def _enough(ctx: Context, draws: Draws, key: Key) -> bool:
    """analysis.claims.get's test of a cell (its seeds are the same number in every draw)."""
    return key in draws and draws[key].shape[1] > 0 and draws[key].shape[1] >= ctx.min_seeds


def _near(a: np.ndarray, b: np.ndarray | float) -> np.ndarray:
    """Where ``a`` and ``b`` are within :data:`TIE` of each other (relative)."""
    return np.abs(a - b) <= TIE * (1.0 + np.abs(a) + np.abs(b))


def _verdicts(sims: int, supported: np.ndarray | bool, otherwise: str, unsure: np.ndarray | bool) -> np.ndarray:
    out = np.where(np.broadcast_to(supported, (sims,)), SUPPORTED, otherwise).astype(object)
    out[np.broadcast_to(unsure, (sims,))] = ""
    return out


def _all(sims: int, verdict: str) -> np.ndarray:
    return np.full(sims, verdict, dtype=object)


def _stacked_draws(draws: Draws, keys: Sequence[Key]) -> np.ndarray:
    """:func:`stacked` of every draw: (draws x seeds x cells)."""
    k = min(draws[key].shape[1] for key in keys)
    return np.stack([draws[key][:, :k] for key in keys], axis=2)


def _on_table(rule: Callable[[Context, dict], tuple[str, str]]) -> Callable[[Context, Cells], tuple[str, str]]:
    return lambda ctx, cells: rule(ctx, means_table(cells))


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
        out = np.where(fail, REFUTED, NO_DATA if missing else SUPPORTED).astype(object)
        out[unsure] = ""
        return out

    return judge


