"""F9 (fig:action_repeat): TACO on hopper_hop for action repeat {1,2,4} x K {1,3,5}."""

from __future__ import annotations

from analysis import select
from analysis.claims import best_k_printed
from analysis.context import Context
from paper_figures.bars import render_bars
from paper_figures.registry import ArtifactResult, register

REPEATS = [1, 2, 4]
KS = ["K=1", "K=3", "K=5"]


@register("F9", "Action repeat x K (hopper_hop)", "figure", "fig:action_repeat")
def render(ctx: Context) -> ArtifactResult:
    df = select.action_repeat(ctx.scores, ctx.experiment_map)
    if not df.empty:
        df = df.assign(ar=df["action_repeat"].astype(int), k=df["K"].map(lambda k: f"K={int(k)}"))
    else:
        df = df.assign(ar=[], k=[])
    repeats = sorted(set(REPEATS) | set(df["ar"]))
    ks = sorted(set(KS) | set(df["k"]), key=lambda s: int(s.split("=")[1]))
    best_k = list(best_k_printed(ctx.paper).items())  # appendix B's prose (claim_numbers.csv)
    caption = (
        "Return at the frame budget of TACO on hopper_hop for each action repeat and prediction horizon K "
        "(experiment 'action_repeat'). The paper draws this figure without numbers; the diamond at action "
        "repeat 2, K=3 is Table 1's TACO value (the paper's default setting for hopper_hop). The paper's "
        f"best K: {best_k[0][1]} at action repeat {best_k[0][0]}, " + ", ".join(f"{k} at {a}" for a, k in best_k[1:])
        + "."
    )
    result, _ = render_bars(
        ctx, "F9", "Action repeat and K on Hopper Hop", df, "ar", "k", repeats, ks, caption,
        f"return at {ctx.frames_budget(df).text()}",
        paper=lambda k: ctx.paper.online_value("hopper_hop", "TACO") if (k["ar"], k["k"]) == (2, "K=3") else None,
        x_labels=lambda a: f"action repeat {a}", figsize=(7.5, 4.0), varied=("action_repeat",),
    )
    return result
