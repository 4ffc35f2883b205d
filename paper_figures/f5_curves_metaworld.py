"""F5 (fig:online_rl_mw): Meta-world success-rate curves, TACO against DrQ-v2 and A-LIX."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from analysis.paper import METAWORLD6
from paper_figures.curves import render_curves
from paper_figures.registry import ArtifactResult, register

LABELS = ["TACO", "DrQ-v2", "A-LIX"]


@register("F5", "Meta-world success-rate curves", "figure", "fig:online_rl_mw")
def render(ctx: Context) -> ArtifactResult:
    curves = select.metaworld(ctx.curves, ctx.experiment_map)
    tasks = list(METAWORLD6) + (sorted(set(curves["task"]) - set(METAWORLD6)) if not curves.empty else [])
    caption = ("Evaluation success rate (% of evaluation episodes that succeed at any step) against environment "
               "frames on the Meta-world tasks (experiment 'metaworld'). The paper prints no numbers for this figure.")
    return render_curves(ctx, "F5", "Meta-world learning curves", curves, tasks, LABELS, caption, "success rate (%)")
