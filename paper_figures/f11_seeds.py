"""F11 (fig:robustness_analysis): per-seed learning curves of TACO and DrQ-v2 on nine DMC tasks."""

from __future__ import annotations

import pandas as pd

from analysis import select
from analysis.context import Context
from analysis.identity import task_display
from analysis.paper import DMC9
from analysis.robustness import BROKEN_FRACTION, seed_spread
from analysis.tables import fmt_num, write_table
from paper_figures.curves import render_curves
from paper_figures.registry import ArtifactResult, register

LABELS = ["TACO", "DrQ-v2"]


@register("F11", "Seed robustness, nine DMC tasks", "figure", "fig:robustness_analysis")
def render(ctx: Context) -> ArtifactResult:
    curves = select.online_main(ctx.curves, ctx.experiment_map)
    curves = curves[curves["label"].isin(LABELS)] if not curves.empty else curves
    caption = "Evaluation return of every seed of TACO and DrQ-v2 on the nine DMC tasks (experiment 'main')."
    result = render_curves(ctx, "F11", "Per-seed learning curves", curves, DMC9, LABELS, caption, "episode return",
                           per_seed=True)
    scores = select.online_main(ctx.scores, ctx.experiment_map)
    scores = scores[scores["label"].isin(LABELS)] if not scores.empty else scores
    spread = seed_spread(scores)
    disp = []
    for task in DMC9:
        for lab in LABELS:
            r = spread[(spread["task"] == task) & (spread["label"] == lab)]
            r = r.iloc[0] if not r.empty else None
            disp.append(
                {
                    "Task": task_display(task),
                    "Method": lab,
                    "n": 0 if r is None else int(r["n"]),
                    "Mean": fmt_num(None if r is None else r["mean"]),
                    "Std (ddof=1)": fmt_num(None if r is None else r["std"]),
                    "Min": fmt_num(None if r is None else r["min"]),
                    "Max": fmt_num(None if r is None else r["max"]),
                    "Broken seeds": "—" if r is None else int(r["broken"]),
                }
            )
    tcap = (f"Spread over seeds of the return at {ctx.frames_budget(scores).text()} (the paper gives no numbers for "
            "this figure). "
            f"A seed is 'broken' if its return is below {BROKEN_FRACTION:g} x the median of its cell.")
    table = write_table(ctx.out_dir, "F11", spread, tcap, pd.DataFrame(disp))
    result.tables.append(table)
    return result
