"""Reference returns for the normalised offline score: 100 x return / best online TACO return on the task.

The paper's Table 1 TACO means at 1M frames (tab:online_table), read from the one packaged copy of Table 1
(repro/config/data/online_rl_table.csv, which the analysis reads too).
A dataset whose manifest knows its source run's best evaluation return (``source.best_return``) is
normalised by that instead; which one was used is the eval.csv column ``score_reference``.
"""

from __future__ import annotations

import math
from typing import Any

from repro.config.paper_defaults import online_means

PAPER_TACO_RETURN: dict[str, float] = online_means("TACO")


def score_reference(task: str, source: dict[str, Any] | None) -> tuple[float | None, str]:
    """(reference return, 'source' | 'paper' | 'none')."""
    best = (source or {}).get("best_return")
    if isinstance(best, (int, float)) and not isinstance(best, bool) and math.isfinite(best) and best > 0:
        return float(best), "source"
    if task in PAPER_TACO_RETURN:
        return PAPER_TACO_RETURN[task], "paper"
    return None, "none"


def normalized_score(mean_return: float, reference: float | None) -> float | None:
    if reference is None or not math.isfinite(mean_return):
        return None
    return 100.0 * mean_return / reference
