"""F10 (fig:action_representation_dim): TACO on quadruped_run across latent action dimensions."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from analysis.identity import default_latent_dim
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

DIMS = [6, 15, 24]  # the text's extremes and the default ceil(1.25 x 12)


@register("F10", "Latent action dimension (quadruped_run)", "figure", "fig:action_representation_dim")
def render(ctx: Context) -> ArtifactResult:
    df = select.action_dim(ctx.scores, ctx.experiment_map)
    df = df.assign(arm="TACO") if not df.empty else df.assign(arm=[], dim=[])
    dims = sorted(set(DIMS) | set(df["dim"]))
    default = default_latent_dim("quadruped_run")
    caption = (
        "Return at the frame budget of TACO on quadruped_run (|A| = 12) for each latent action dimension "
        f"(experiment 'action_dim'; a null dimension in the config is the default ceil(1.25 x 12) = {default}). "
        "The paper's error bars are the std over 8 seeds; here they are 95% CIs (the table gives the std). "
        "The diamond at the default dimension is Table 1's TACO value."
    )
    result, _ = render_bars(
        ctx, "F10", "Latent action dimension on Quadruped Run", df, "dim", "arm", dims, ["TACO"], caption,
        f"return at {ctx.budget_text()}",
        paper=lambda k: ctx.paper.online_value("quadruped_run", "TACO") if k["dim"] == default else None,
        x_labels=lambda d: f"{d}" + (" (default)" if d == default else ""), figsize=(7.0, 4.0), hide=["Arm"],
    )
    return result
