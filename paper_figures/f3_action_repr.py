"""F3 (fig:action_representation): TACO with vs without action representation, and DrQ-v2, at 1M."""

from __future__ import annotations

from analysis import select
from analysis.context import Context
from analysis.identity import task_display
from analysis.paper import PaperData
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

NAMED_TASKS = ["quadruped_run", "reacher_hard", "hopper_hop"]
LABELS = ["TACO", "TACO w/o action repr", "DrQ-v2"]


def implied_no_repr(paper: PaperData) -> dict[str, tuple[float, str]]:
    """TACO w/o action repr, drawn without numbers in the paper, as section 5.1's percentages (claim_numbers.csv)
    imply it from Table 1, by task: (value, how it is implied, e.g. "541/1.122"). TACO is 12.2% above it on
    quadruped_run and 70.4% on hopper_hop; it is 51% above DrQ-v2 on reacher_hard."""
    number = paper.claim_number
    from_taco = {"quadruped_run": number("action_repr_gain", "gain_low_percent"),
                 "hopper_hop": number("action_repr_gain", "gain_high_percent")}
    out: dict[str, tuple[float, str]] = {}
    for task, pct in from_taco.items():
        taco = paper.online_value(task, "TACO")
        if taco is not None:
            out[task] = (taco[0] / (1 + pct / 100), f"{taco[0]:g}/{1 + pct / 100:g}")
    over = number("no_action_repr_vs_drqv2", "reacher_hard_percent")
    drq = paper.online_value("reacher_hard", "DrQ-v2")
    if drq is not None:
        out["reacher_hard"] = (drq[0] * (1 + over / 100), f"{drq[0]:g} x {1 + over / 100:g}")
    return out


def paper_value(ctx: Context, key: dict) -> tuple[float, float | None] | None:
    if key["label"] == "TACO w/o action repr":
        implied = implied_no_repr(ctx.paper).get(key["task"])
        return None if implied is None else (round(implied[0], 1), None)
    method = "TACO" if key["label"] == "TACO" else "DrQ-v2"
    return ctx.paper.online_value(key["task"], method)


@register("F3", "With vs without action representation", "figure", "fig:action_representation")
def render(ctx: Context) -> ArtifactResult:
    df = select.action_repr(ctx.scores, ctx.experiment_map)
    extra = sorted(set(df.loc[df["experiment"] != "main", "task"]) - set(NAMED_TASKS)) if not df.empty else []
    tasks = NAMED_TASKS + extra
    df = df[df["task"].isin(tasks)] if not df.empty else df
    caption = (
        "Return at the frame budget of TACO, TACO without the action encoder (experiment 'action_repr') and "
        "DrQ-v2 on the paper's named tasks plus any other task of the sweep. Paper values: TACO and DrQ-v2 "
        "from Table 1; TACO w/o action representation implied by the text's percentages ("
        + ", ".join(f"{t} {how}" for t, (_, how) in implied_no_repr(ctx.paper).items()) + ")."
    )
    result, _ = render_bars(ctx, "F3", "Action representation", df, "task", "label", tasks, LABELS, caption,
                            f"return at {ctx.frames_budget(df).text()}", paper=lambda k: paper_value(ctx, k),
                            x_labels=task_display)
    return result
