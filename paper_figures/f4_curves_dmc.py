"""F4 (fig:online_rl): learning curves on the nine DMC tasks, TACO against DrQ-v2 and A-LIX."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from analysis.paper import DMC9
from paper_figures.curves import render_curves
from paper_figures.registry import ArtifactResult, register

LABELS = ["TACO", "DrQ-v2", "A-LIX"]


@register("F4", "Learning curves, nine DMC tasks", "figure", "fig:online_rl")
def render(ctx: Context) -> ArtifactResult:
    curves = select.online_main(ctx.curves, ctx.experiment_map)
    curves = curves[curves["label"].isin(LABELS)] if not curves.empty else curves
    marks = {}
    for task in DMC9:
        for lab in LABELS:
            v = ctx.paper.online_value(task, lab)
            if v is not None:
                marks[(task, lab)] = v[0]
    caption = "Evaluation return against environment frames on the nine DMC tasks (experiment 'main')."
    return render_curves(ctx, "F4", "DMC learning curves", curves, DMC9, LABELS, caption, "episode return",
                         paper_marks=marks, published=True)
