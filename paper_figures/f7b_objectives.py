"""F7b (sfig:objective_ablation): TACO on quadruped_run with one objective removed at a time."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

VARIANTS = ["full", "no TACO", "no CURL", "no reward"]


@register("F7b", "Objective removal (quadruped_run)", "figure", "sfig:objective_ablation")
def render(ctx: Context) -> ArtifactResult:
    df = select.objective_removal(ctx.scores, ctx.experiment_map)
    df = df.assign(arm="TACO") if not df.empty else df.assign(arm=[])
    caption = (
        "Return at the frame budget on quadruped_run of TACO with all objectives (TACO + CURL + reward "
        "prediction) and with one removed (experiment 'objective_removal'). The paper draws this figure "
        "without numbers; the diamond on 'full' is Table 1's TACO value."
    )
    result, _ = render_bars(
        ctx, "F7b", "Objective removal on Quadruped Run", df, "label", "arm", VARIANTS, ["TACO"], caption,
        f"return at {ctx.frames_budget(df).text()}",
        paper=lambda k: ctx.paper.online_value("quadruped_run", "TACO") if k["label"] == "full" else None,
        figsize=(6.5, 4.0), hide=["Arm"],
    )
    return result
