"""F8 (fig:step_size): TACO with prediction horizon K=1 and K=3 against DrQ-v2 on nine DMC tasks."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from analysis.identity import task_display
from analysis.paper import DMC9
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

LABELS = ["K=1", "K=3", "DrQ-v2"]


def default_k(task: str) -> int | None:
    """The K the paper's Table 1 uses, as the task's config file sets it (repro/conf/task/<task>.yaml: 1 on
    quadruped_run and walker_run, 3 elsewhere, Appendix B); None for a task without a config file. The composition
    is kept in the command's cache (analysis/composed.py)."""
    from analysis.composed import composed_value
    from repro.config.compose import ConfigError

    try:
        return int(composed_value([f"task={task}"], "agent.K"))
    except ConfigError:
        return None


@register("F8", "Prediction horizon K", "figure", "fig:step_size")
def render(ctx: Context) -> ArtifactResult:
    df = select.horizon(ctx.scores, ctx.experiment_map)
    extra = sorted(set(df["task"]) - set(DMC9)) if not df.empty else []

    def paper(key: dict):
        if key["label"] == "DrQ-v2":
            return ctx.paper.online_value(key["task"], "DrQ-v2")
        if key["label"] == f"K={default_k(key['task'])}":
            return ctx.paper.online_value(key["task"], "TACO")
        return None

    caption = (
        "Return at the frame budget of TACO with K=1 and K=3 and of DrQ-v2 (experiment 'horizon', falling "
        "back to 'main' per cell). The paper draws this figure without numbers; diamonds are Table 1's values "
        "(TACO at its default K per task: 1 on quadruped_run and walker_run, 3 elsewhere)."
    )
    result, _ = render_bars(ctx, "F8", "Prediction horizon K", df, "task", "label", [*DMC9, *extra], LABELS, caption,
                            f"return at {ctx.frames_budget(df).text()}", paper=paper, x_labels=task_display,
                            figsize=(13, 4.2))
    return result
