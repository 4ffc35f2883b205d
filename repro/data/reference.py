"""Reference returns for the normalised offline score: 100 x return / best online TACO return on the task.

The paper's Table 1 TACO means at 1M frames (tab:online_table; the same numbers as
analysis/paper_data/online_rl_table.csv, kept here because core code does not read analysis data).
A dataset whose manifest knows its source run's best evaluation return (``source.best_return``) is
normalised by that instead; which one was used is the eval.csv column ``score_reference``.
"""

from __future__ import annotations

import math
from typing import Any

PAPER_TACO_RETURN: dict[str, float] = {
    "quadruped_run": 541.0, "hopper_hop": 261.0, "walker_run": 637.0, "quadruped_walk": 793.0,
    "cheetah_run": 821.0, "finger_turn_hard": 632.0, "acrobot_swingup": 241.0, "reacher_hard": 883.0,
    "reach_duplo": 234.0,
}


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
