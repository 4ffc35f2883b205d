"""Every claim, listed once (:data:`SPECS`: the families' specs, analysis/claims/online.py, offline.py and
ablations.py), judged at its own budget (:func:`evaluate_claims`) and written (:func:`write_claims`)."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from analysis.claim_budget import claim_runs, load_budgets
from analysis.claims import ablations, offline, online
from analysis.claims.core import NO_DATA, REFUTED, SUPPORTED, ClaimSpec, Verdict, read_claim, short_of_budget
from analysis.claims.online import PUBLISHED_GAIN_ID
from analysis.context import Context
from analysis.paper import PaperData
from analysis.tables import TableOutput, write_table

# Every claim of claims.csv, each once (tests/test_claim_sources.py), by family; claim_specs gives claims.csv's order.
SPECS: tuple[ClaimSpec, ...] = (*online.SPECS, *ablations.SPECS, *offline.SPECS)
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


def evaluate_claims(ctx: Context, specs: Sequence[ClaimSpec] | None = None) -> list[Verdict]:
    """One verdict per claim of :func:`claim_specs` (claims.csv's order, the reading of online_avg_gain against the
    published DrQ-v2 curves after it), each at the claim's own budget. ``specs``: ``claim_specs(ctx.paper)`` where the
    caller has it (the report lists the claims once for the verdicts and the power), None: listed here."""
    budgets = load_budgets()
    text = dict(zip(ctx.paper.claims["id"], ctx.paper.claims["claim"]))
    out = []
    for spec in claim_specs(ctx.paper) if specs is None else specs:
        claim = text[spec.claim_id] + (f" [{spec.note}]" if spec.note else "")
        budget = budgets.get(spec.claim_id)
        if budget is None:
            out.append(Verdict(spec.id, claim, NO_DATA, "no budget for this claim in claim_budgets.csv",
                               spec.rule_text(ctx.paper)))
            continue
        verdict, evidence, label = read_claim(ctx, budget, short_of_budget(ctx, budget), spec.check)
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


def write_claims(ctx: Context, verdicts: Sequence[Verdict]) -> TableOutput:
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


