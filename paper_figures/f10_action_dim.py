"""F10 (fig:action_representation_dim): TACO on quadruped_run across latent action dimensions."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

PAPER_DEFAULT = 15  # the paper's default for |A| = 12 (Appendix D: ceil(1.25 |A|)), where Table 1's value goes
DIMS = [6, PAPER_DEFAULT, 24]  # the text's extremes and the paper's default


@register("F10", "Latent action dimension (quadruped_run)", "figure", "fig:action_representation_dim")
def render(ctx: Context) -> ArtifactResult:
    df = select.action_dim_runs(ctx.scores, ctx.experiment_map)
    df = df.assign(arm="TACO") if not df.empty else df.assign(arm=[], dim=[])
    dims = sorted(set(DIMS) | set(df["dim"]))
    caption = (
        "Return at the frame budget of TACO on quadruped_run (|A| = 12) for each latent action dimension "
        "(experiment 'action_dim'). Each run sits at the dimension it recorded as used (resolved.json): a run "
        "that leaves agent.latent_action_dim unset uses its agent.latent_action_rounding (upstream, the "
        "default: 16; paper: 15). "
        "The paper's error bars are the std over 8 seeds; here they are 95% CIs (the table gives the std). "
        f"The diamond at {PAPER_DEFAULT}, the paper's default, is Table 1's TACO value."
    )
    result, _ = render_bars(
        ctx, "F10", "Latent action dimension on Quadruped Run", df, "dim", "arm", dims, ["TACO"], caption,
        f"return at {ctx.frames_budget(df).text()}",
        paper=lambda k: ctx.paper.online_value("quadruped_run", "TACO") if k["dim"] == PAPER_DEFAULT else None,
        x_labels=lambda d: f"{d}" + (" (paper default)" if d == PAPER_DEFAULT else ""), figsize=(7.0, 4.0),
        hide=["Arm"],
    )
    return result
