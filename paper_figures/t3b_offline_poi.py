"""T3b (derived from tab:offline_table): paired ±TACO comparison of the offline runs, rliable's probability
of improvement per task and dataset and over all 12 pairs."""

from __future__ import annotations

import pandas as pd

from analysis.comparable import paper_updates, short_number
from analysis.context import Context
from analysis.identity import task_display
from analysis.offline_tables import POI_MAX_REPS, offline_runs, taco_poi
from analysis.tables import EMPTY, fmt_ci, fmt_num, write_table
from paper_figures.registry import ArtifactResult, register


@register("T3b", "Offline RL: ±TACO probability of improvement", "table", "tab:offline_table")
def render(ctx: Context) -> ArtifactResult:
    runs = offline_runs(ctx.scores, ctx.experiment_map)
    raw = taco_poi(runs, ctx.paper, ctx.reps, ctx.seed)
    disp = pd.DataFrame({
        "Task": [t if t == "All" else task_display(t) for t in raw["task"]],
        "Dataset": raw["dataset"],
        "Comparison": [f"{m} vs {b}" for m, b in zip(raw["method"], raw["baseline"])],
        "n": [f"{a} / {b}" for a, b in zip(raw["n_method"], raw["n_baseline"])],
        "Mean (+TACO / base)": [EMPTY if pd.isna(a) and pd.isna(b) else f"{fmt_num(a)} / {fmt_num(b)}"
                                for a, b in zip(raw["mean_method"], raw["mean_baseline"])],
        "P(+TACO > base)": [fmt_num(p, 2) for p in raw["poi"]],
        "95% CI": [fmt_ci(lo, hi, 2) for lo, hi in zip(raw["ci_low"], raw["ci_high"])],
        "Note": raw["note"],
    })
    reps = min(ctx.reps, POI_MAX_REPS)
    caption = ("Paired ±TACO comparison of the offline runs: rliable's probability of improvement P(X+TACO > X) "
               "of the normalised scores at each run's own budget, per task and dataset and over all 12 pairs "
               "(rliable's average over tasks), with its 95% stratified-bootstrap CI.")
    notes = [f"Finished runs only (n: +TACO / base); {reps:,} bootstrap repetitions (random state {ctx.seed}); "
             "0.5 means neither is better; the paper reports means only, so there is no paper column.",
             _budget_note(runs)]
    table = write_table(ctx.out_dir, "T3b", raw, caption, disp, notes)
    return ArtifactResult("T3b", "Offline ±TACO", caption, tables=[table], notes=notes,
                          has_runs=bool(raw["poi"].notna().any()))


def _budget_note(runs: pd.DataFrame) -> str:
    """The budgets of the finished runs compared, in gradient updates, and whether they reach the budget from which
    a run is compared with the paper's Table 3 (analysis.comparable.paper_updates)."""
    paper = paper_updates()
    done = runs[runs["reached"].astype(bool)] if not runs.empty else runs
    updates = sorted({int(u) for u in done["offline_updates"].dropna()}) if not done.empty else []
    if not updates:
        return "Budget: each run's own offline.updates, in gradient updates."
    below = updates[0] < paper.value
    return (f"Budget: each run's own offline.updates, in gradient updates (these runs: "
            f"{', '.join(short_number(u) for u in updates)})"
            + (f"; runs below {short_number(paper.value)} updates are not comparable with the paper's Table 3, so "
               "these probabilities say nothing about its claims." if below else "."))
