"""F7a (sfig:batch_size_quadruped_run): TACO and DrQ-v2 on quadruped_run across batch sizes."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

BATCHES = [256, 512, 1024]


@register("F7a", "Batch size (quadruped_run)", "figure", "sfig:batch_size_quadruped_run")
def render(ctx: Context) -> ArtifactResult:
    df = select.batch_size(ctx.scores, ctx.experiment_map)
    if not df.empty:
        df = df.assign(batch=df["batch_size"].astype(int), label=df["method"])
    batches = sorted(set(BATCHES) | (set(df["batch"]) if not df.empty else set()))

    def paper(key: dict):
        if (key["label"], key["batch"]) in (("TACO", 1024), ("DrQ-v2", 256)):
            return ctx.paper.online_value("quadruped_run", key["label"])
        return None

    caption = (
        "Return at the frame budget on quadruped_run for TACO and DrQ-v2 at each batch size (experiment "
        "'batch_size'). The paper draws this figure without numbers; the diamonds are Table 1's values at "
        "each method's default batch size (TACO 1024, DrQ-v2 256)."
    )
    result, _ = render_bars(ctx, "F7a", "Batch size on Quadruped Run", df, "batch", "label", batches,
                            ["TACO", "DrQ-v2"], caption, f"return at {ctx.frames_budget(df).text()}", paper=paper,
                            x_labels=lambda b: f"B={b}")
    return result
