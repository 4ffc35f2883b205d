"""Every claim, listed once (:data:`SPECS`), judged at its own budget (:func:`evaluate_claims`) and written
(:func:`write_claims`)."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from analysis.calibration import SOURCE_TEXT
from analysis.cells import table1_cells, table2_cells, table3_cells
from analysis.claim_budget import claim_runs, load_budgets
from analysis.claims.ablations import (
    _FIGURE_ONLY,
    COMPARABLE_WITHIN,
    REPR_TASKS,
    _action_dim,
    _action_repeat,
    _action_repeat_rule_text,
    _action_repr_gain,
    _batch,
    _horizon,
    _no_repr_vs_drqv2,
    _objectives,
    _repr_observed,
    _speed,
    _speed_rule_text,
    _tsne,
    _vs_repr,
    vs_repr_pairs,
    vs_repr_rule,
)
from analysis.claims.core import (
    NO_DATA,
    REFUTED,
    SUPPORTED,
    ClaimSpec,
    Simulation,
    Verdict,
    _reading,
    _short_of_budget,
)
from analysis.claims.draws import _on_table, universal_batch
from analysis.claims.offline import (
    _OFFLINE_NOTE,
    CI_REPS,
    CI_SIMS,
    OFFLINE_AVERAGED,
    _judge_offline_average,
    _offline_average,
    _offline_average_batch,
    _offline_gain,
    _offline_observed,
    offline_gain_pairs,
    offline_gain_rule,
)
from analysis.claims.online import (
    LESS_SPREAD_TASKS,
    MODEL_BASED_WINS,
    PUBLISHED_GAIN_ID,
    _beats_drqv2,
    _beats_model_based,
    _gain_batch,
    _gain_rule_text,
    _judge_gain,
    _judge_manipulator,
    _judge_published_gain,
    _judge_seeds,
    _longer,
    _manipulator,
    _manipulator_batch,
    _manipulator_note,
    _manipulator_rule_text,
    _manipulator_sources,
    _metaworld,
    _model_based_batch,
    _online_avg_gain,
    _online_avg_gain_published,
    _online_observed,
    _online_sources,
    _published_gain_batch,
    _published_gain_rule_text,
    _published_sources,
    _reacher_rule_text,
    _reacher_speed,
    _seeds,
    _seeds_batch,
    _seeds_observed,
    beats_drqv2_pairs,
    beats_drqv2_rule,
    beats_model_based_rule,
)
from analysis.context import Context
from analysis.paper import DMC9, OFFLINE_TASKS, PaperData
from analysis.tables import write_table
from analysis.tsne import CLUSTER_THRESHOLD

# Every claim of claims.csv, in its order, each once (tests/test_claim_sources.py).
SPECS: tuple[ClaimSpec, ...] = (
    ClaimSpec("online_avg_gain", _online_avg_gain,
              _gain_rule_text,
              Simulation(_online_sources, _judge_gain, _online_observed, DMC9, batch=_gain_batch)),
    ClaimSpec(PUBLISHED_GAIN_ID, _online_avg_gain_published, _published_gain_rule_text,
              Simulation(_published_sources, _judge_published_gain, _online_observed, DMC9,
                         notes=("DrQ-v2 is the published curves as published (fixed data, as `repro claims` reads "
                                "them)",), batch=_published_gain_batch),
              reading_of="online_avg_gain",
              note=f"read against DrQ-v2 as published by its authors, not against your DrQ-v2 runs: {SOURCE_TEXT}",
              audit=("online_gain_vs_published",)),
    ClaimSpec("online_beats_drqv2_all", _beats_drqv2,
              "TACO mean > DrQ-v2 mean on each of the 9 tasks",
              Simulation(_online_sources, _on_table(beats_drqv2_rule), _online_observed, DMC9,
                         batch=universal_batch(lambda c: beats_drqv2_pairs()))),
    ClaimSpec("online_beats_model_based", _beats_model_based,
              f"TACO mean > both DreamerV3 and TD-MPC on >= {MODEL_BASED_WINS} of 9 tasks (baselines from runs, "
              "else the paper's Table 1)",
              Simulation(lambda ctx, budget: table1_cells(ctx, DMC9), _on_table(beats_model_based_rule),
                         _online_observed, DMC9,
                         notes=("DreamerV3 and TD-MPC are Table 1's printed means (not rerun by any sweep), as the "
                                "rule reads them",), batch=_model_based_batch)),
    ClaimSpec("reacher_speed", _reacher_speed, _reacher_rule_text,
              not_simulated="its rule reads TACO's and DrQ-v2's mean learning curves up to 1.5M frames; the paper "
                            "gives TACO's curve only as a figure (F4), with no per-seed or per-frame numbers"),
    ClaimSpec("longer_training", _longer,
              "TACO mean > DrQ-v2 mean at the last common frame (>= the budget, 2M) on quadruped_run, "
              "hopper_hop, walker_run, cheetah_run",
              not_simulated="its rule reads both methods at 2M frames; the paper gives those only as learning-curve "
                            "figures (F4), with no numbers at 2M"),
    ClaimSpec("metaworld", _metaworld,
              "TACO mean success > each baseline's (DrQ-v2; A-LIX if run) on each of the 6 tasks at the budget",
              not_simulated="the paper gives Meta-world success rates only as figures (F5), with no mean or std per "
                            "task"),
    ClaimSpec("action_repr_gain", _action_repr_gain,
              "TACO mean > TACO w/o action repr mean on every task of the action_repr sweep (named: "
              "quadruped_run, hopper_hop, reacher_hard)",
              not_simulated="the paper gives the gains as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("no_action_repr_vs_drqv2", _no_repr_vs_drqv2,
              "TACO w/o action repr beats DrQ-v2 on quadruped_run and reacher_hard, and is within "
              f"±{COMPARABLE_WITHIN:.0%} of DrQ-v2 on the other tasks of the sweep",
              not_simulated="the paper gives these as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("tsne_clusters", _tsne,
              f"silhouette of the 4 centroid labels on the t-SNE embedding: latent >= {CLUSTER_THRESHOLD} "
              f"and raw < {CLUSTER_THRESHOLD}",
              not_simulated="one trained agent and a t-SNE embedding: not a statistic over seeds"),
    ClaimSpec("batch_size", _batch,
              "on quadruped_run TACO's mean is non-decreasing in batch size and >= 10% higher at the largest "
              "than at the smallest; DrQ-v2's range is <= 15% of its mean",
              not_simulated=_FIGURE_ONLY.format("the batch-size results", "F7a")),
    ClaimSpec("objective_removal", _objectives,
              "on quadruped_run the drop full - no TACO is positive and larger than the drops of no "
              "CURL and no reward",
              not_simulated="the paper gives the ablation only as a figure (F7b), with no numbers"),
    ClaimSpec("vs_repr_objectives", _vs_repr,
              "TACO mean > each other objective of Table 2 (each of its methods but TACO and DrQ-v2; where the "
              "paper has its value) on each of the 5 tasks",
              Simulation(lambda ctx, budget: table2_cells(ctx, REPR_TASKS), _on_table(vs_repr_rule), _repr_observed,
                         REPR_TASKS, batch=universal_batch(vs_repr_pairs))),
    ClaimSpec("offline_gain", _offline_gain,
              "return of X+TACO > X for X in TD3+BC, CQL on each of the 12 task/dataset pairs",
              Simulation(lambda ctx, budget: table3_cells(ctx, OFFLINE_AVERAGED), _on_table(offline_gain_rule),
                         _offline_observed, OFFLINE_TASKS, notes=(_OFFLINE_NOTE,),
                         batch=universal_batch(lambda c: offline_gain_pairs()))),
    ClaimSpec("offline_average", _offline_average,
              "each printed average of Table 3's average row (TD3+BC+TACO, TD3+BC, CQL+TACO, CQL; "
              "repro_data/paper/offline_average.csv) lies in the 95% CI of the reproduced average normalised score "
              "over the 12 pairs",
              Simulation(lambda ctx, budget: table3_cells(ctx, OFFLINE_AVERAGED), _judge_offline_average,
                         _offline_observed, OFFLINE_TASKS, sims=CI_SIMS, reps=CI_REPS,
                         batch=_offline_average_batch)),
    ClaimSpec("horizon_choice", _horizon,
              "K=3 > K=1 on hopper_hop, quadruped_walk, acrobot_swingup, reacher_hard; K=1 > K=3 on "
              "quadruped_run, walker_run; K=1 and K=3 > DrQ-v2 on all 9 tasks",
              not_simulated=_FIGURE_ONLY.format("K=1 and K=3", "F8")),
    ClaimSpec("action_repeat", _action_repeat, _action_repeat_rule_text,
              not_simulated=_FIGURE_ONLY.format("the action-repeat results", "F9")),
    ClaimSpec("action_dim", _action_dim,
              "on quadruped_run the means at dims 6 and 24 are below every intermediate dim's, and the "
              "intermediate dims' range is <= 15% of their mean",
              not_simulated=_FIGURE_ONLY.format("the latent-dimension results", "appendix E")),
    ClaimSpec("speed", _speed, _speed_rule_text,
              not_simulated="a timing on your hardware (`repro bench`), not a statistic over seeds"),
    ClaimSpec("seed_robustness", _seeds,
              f"TACO's std over seeds < DrQ-v2's on >= {LESS_SPREAD_TASKS} of the 9 tasks, and DrQ-v2 has >= 1 broken "
              "seed (below half its cell's median)",
              Simulation(_online_sources, _judge_seeds, _seeds_observed, DMC9,
                         notes=("a broken seed is one below half its cell's median: normal cells almost never have "
                                "one, so DrQ-v2's published values carry the claim's second half",),
                         batch=_seeds_batch)),
    ClaimSpec("manipulator", _manipulator, _manipulator_rule_text,
              Simulation(_manipulator_sources, _judge_manipulator, None, ("manipulator_bring_ball",),
                         notes=(_manipulator_note, "not conditioned on runs (the rule reads learning curves)"),
                         batch=_manipulator_batch)),
)


SPEC_OF = {s.id: s for s in SPECS}


if len(SPEC_OF) != len(SPECS):  # a claim defined twice: one of its definitions would be silently dropped
    raise ValueError(f"claims defined twice: {sorted({s.id for s in SPECS if sum(t.id == s.id for t in SPECS) > 1})}")


def claim_specs(paper: PaperData) -> list[ClaimSpec]:
    """The claims every reader lists (`repro claims`, `repro plan --claims`, the report): one spec per claim of
    ``paper``'s claims.csv in its order, each followed by its other readings. Raises ValueError when a claim of
    claims.csv has no spec or a spec judges a claim it does not have."""
    ids = list(paper.claims["id"])
    missing = [i for i in ids if i not in SPEC_OF]
    extra = [s.id for s in SPECS if s.claim_id not in ids]
    if missing or extra:
        raise ValueError(f"claims.csv and analysis.claims.SPECS disagree: no spec for {missing}; no claim for {extra}")
    return [s for i in ids for s in [SPEC_OF[i], *(r for r in SPECS if r.reading_of == i)]]


def evaluate_claims(ctx: Context) -> list[Verdict]:
    """One verdict per claim of :func:`claim_specs` (claims.csv's order, the reading of online_avg_gain against the
    published DrQ-v2 curves after it), each at the claim's own budget."""
    budgets = load_budgets()
    text = dict(zip(ctx.paper.claims["id"], ctx.paper.claims["claim"]))
    out = []
    for spec in claim_specs(ctx.paper):
        claim = text[spec.claim_id] + (f" [{spec.note}]" if spec.note else "")
        budget = budgets.get(spec.claim_id)
        if budget is None:
            out.append(Verdict(spec.id, claim, NO_DATA, "no budget for this claim in claim_budgets.csv",
                               spec.rule_text(ctx.paper)))
            continue
        verdict, evidence, label = _reading(ctx, budget, _short_of_budget(ctx, budget), spec.check)
        runs = claim_runs(ctx.scores, budget, ctx.experiment_map, offline=budget.kind == "offline_updates")
        out.append(Verdict(spec.id, claim, verdict, evidence, spec.rule_text(ctx.paper), budget.column(runs),
                           max(budget.min_seeds, ctx.min_seeds), label))
    return out


def verdict_counts(verdicts: Sequence[Verdict]) -> str:
    """'21 rows (...): 2 supported, 1 refuted, 18 not enough data (5 with an indicative reading, not a verdict)': the
    counts add up to the rows of the claims table, the reading of online_avg_gain against the published DrQ-v2
    curves (a row of its own) among them, named."""
    counts = {k: sum(v.verdict == k for v in verdicts) for k in (SUPPORTED, REFUTED, NO_DATA)}
    text = ", ".join(f"{counts[k]} {k}" for k in (SUPPORTED, REFUTED, NO_DATA))
    n_ind = sum(bool(v.indicative) for v in verdicts)
    text += f" ({n_ind} with an indicative reading, not a verdict)" if n_ind else ""
    readings = [v for v in verdicts if v.id == PUBLISHED_GAIN_ID]
    what = (f"the paper's {len(verdicts) - len(readings)} claims and online_avg_gain read against the published "
            "DrQ-v2 curves" if readings else f"the paper's {len(verdicts)} claims")
    return f"{len(verdicts)} rows ({what}): {text}"


def claims_frame(verdicts: Sequence[Verdict]) -> pd.DataFrame:
    """The display table of the claims: Claim, Verdict (or indicative label), Budget, Seeds, Numbers, Rule."""
    return pd.DataFrame({"Claim": [v.id for v in verdicts], "Verdict": [v.shown for v in verdicts],
                         "Budget": [v.budget for v in verdicts],
                         "Seeds": [f">= {v.min_seeds}" if v.min_seeds else "" for v in verdicts],
                         "Numbers": [v.evidence for v in verdicts], "Rule": [v.rule for v in verdicts]})


def write_claims(ctx: Context, verdicts: Sequence[Verdict]):
    """Write ``claims.csv/.md/.tex`` to ``ctx.out_dir``."""
    raw = pd.DataFrame([v.__dict__ for v in verdicts])
    caption = f"Verdict on each claim of the paper from the reproduced runs ({verdict_counts(verdicts)})."
    notes = ["Each claim is judged at its own budget (Budget: environment frames = agent steps x action repeat, the "
             "repeat of the claim's runs beside them, the paper's where there are none; offline, gradient "
             "updates) with at least the seeds per cell in Seeds "
             "(analysis/claim_budgets.csv), only from runs that reached that budget; verdicts compare means "
             "with the tolerances in the Rule column; CIs are 95% stratified-bootstrap (rliable)."]
    if any(v.indicative for v in verdicts):
        notes.append("An 'indicative' entry is a reading below the claim's budget or seed count, asked for "
                     "with --indicative: it is not a verdict and counts as not enough data.")
    return write_table(ctx.out_dir, "claims", raw, caption, claims_frame(verdicts), notes)


