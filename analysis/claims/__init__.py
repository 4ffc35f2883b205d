"""A verdict for every claim of ``claims.csv`` from the user's runs: supported / refuted / not enough data.

Rules (also in docs/analysis.md): each claim is judged at its own budget with its own minimum number of
seeds (``analysis/claim_budgets.csv``: 1M frames for most, 1.5M, 2M, 30M, or an offline run's own
configured ``offline.updates``), never at the budget the runs happen to reach. Verdicts compare point
estimates (means over the seeds that reached the claim's budget) with the tolerances written in each
rule; 95% CIs are reported beside them. A cell with fewer seeds than the claim's minimum counts as
missing. A claim about every task ("on each of the nine tasks") is refuted by one counterexample among
the cells that exist, even if others are missing. When the runs fall short, the verdict is "not enough
data" with the reason; on request (``Context.indicative``) an indicative reading at the frames the runs
reach is added, labelled as such and never counted as supported or refuted.

Each claim is defined once, in :data:`SPECS` (:class:`ClaimSpec`: its check and rule, its cells from the runs and
from the paper for the power simulation, or why it is not simulated); `repro claims`, `repro plan --claims`
(analysis/power.py) and the report list the claims through :func:`claim_specs`. A simulated claim's rule is written
once, over a leading draws axis (analysis/claims/draws.py): the user's runs are its one-draw case, the power
simulation its many-draw one. The claims are split by family (analysis/claims/online.py, offline.py, ablations.py);
what they share is analysis/claims/core.py; analysis/claims/catalog.py lists, judges and writes them.
"""

from analysis.claims.ablations import (
    ACTION_REPEATS,
    COMPARABLE_WITHIN,
    REPEAT_HORIZONS,
    REPR_TASKS,
    SPEED_TOLERANCE,
    action_repr_printed,
    best_k_printed,
    paper_slowdown,
    speed_printed,
    vs_repr_pairs,
    vs_repr_rule,
)
from analysis.claims.catalog import (
    SPEC_OF,
    SPECS,
    claim_specs,
    claims_frame,
    evaluate_claims,
    verdict_counts,
    write_claims,
)
from analysis.claims.core import (
    GAIN_TOLERANCE,
    NO_DATA,
    REFUTED,
    SUPPORTED,
    Check,
    ClaimSpec,
    Draws,
    Judge,
    Judgement,
    NotEnoughData,
    Simulation,
    Verdict,
    apart,
    budget_words,
    claim_context,
    frames_apart,
    gain_bar,
    means,
    paper_gain,
    pct,
    vs_text,
)
from analysis.claims.draws import (
    claim_cells,
    enough,
    judged,
    n_draws,
    one_draw,
    require_cells,
    stacked,
    universal,
    verdicts,
)
from analysis.claims.offline import (
    CI_REPS,
    CI_SIMS,
    OFFLINE_AVERAGED,
    offline_average_rule,
    offline_gain_pairs,
    offline_gain_rule,
    offline_printed,
)
from analysis.claims.online import (
    LESS_SPREAD_TASKS,
    MODEL_BASED,
    MODEL_BASED_WINS,
    PUBLISHED_GAIN_ID,
    REACHER_DRQ_FACTOR,
    REACHER_TACO_WITHIN,
    SOLVED_FRACTION,
    avg_gain_rule,
    beats_drqv2_rule,
    manipulator_rule,
    model_based_rule,
    published_gain_rule,
    reacher_printed,
    seed_robustness_rule,
)

__all__ = [
    "ACTION_REPEATS",
    "CI_REPS",
    "CI_SIMS",
    "COMPARABLE_WITHIN",
    "Check",
    "ClaimSpec",
    "Draws",
    "GAIN_TOLERANCE",
    "Judge",
    "Judgement",
    "LESS_SPREAD_TASKS",
    "MODEL_BASED",
    "MODEL_BASED_WINS",
    "NO_DATA",
    "NotEnoughData",
    "OFFLINE_AVERAGED",
    "PUBLISHED_GAIN_ID",
    "REACHER_DRQ_FACTOR",
    "REACHER_TACO_WITHIN",
    "REFUTED",
    "REPEAT_HORIZONS",
    "REPR_TASKS",
    "SOLVED_FRACTION",
    "SPECS",
    "SPEC_OF",
    "SPEED_TOLERANCE",
    "SUPPORTED",
    "Simulation",
    "Verdict",
    "action_repr_printed",
    "apart",
    "avg_gain_rule",
    "beats_drqv2_rule",
    "best_k_printed",
    "budget_words",
    "claim_cells",
    "claim_context",
    "claim_specs",
    "claims_frame",
    "enough",
    "evaluate_claims",
    "frames_apart",
    "gain_bar",
    "judged",
    "manipulator_rule",
    "means",
    "model_based_rule",
    "n_draws",
    "offline_average_rule",
    "offline_gain_pairs",
    "offline_gain_rule",
    "offline_printed",
    "one_draw",
    "paper_gain",
    "paper_slowdown",
    "pct",
    "published_gain_rule",
    "reacher_printed",
    "require_cells",
    "seed_robustness_rule",
    "speed_printed",
    "stacked",
    "universal",
    "verdict_counts",
    "verdicts",
    "vs_repr_pairs",
    "vs_repr_rule",
    "vs_text",
    "write_claims",
]
