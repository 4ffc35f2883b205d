"""T1 (tab:online_table): episode return at 1M frames on nine DMC tasks, TACO and baselines."""

from __future__ import annotations

from analysis import select
from analysis.compare import build_cells
from analysis.context import Context
from paper_figures.common import comparison_table, has_data, relabel
from paper_figures.registry import ArtifactResult, register


def t1_cells(ctx: Context):
    """The comparison cells of Table 1 (task x method), reused by F1."""
    paper = ctx.paper.online
    df = relabel(select.online_main(ctx.scores, ctx.experiment_map), "method")
    expected = [{"task": t, "method": m} for t, m in zip(paper["task"], paper["method"])]
    return build_cells(
        df,
        ["task", "method"],
        expected,
        paper=lambda k: ctx.paper.online_value(k["task"], k["method"]),
        reps=ctx.reps,
        seed=ctx.seed,
    )


@register("T1", "Online DMC: episode return at 1M frames", "table", "tab:online_table")
def render(ctx: Context) -> ArtifactResult:
    cells = t1_cells(ctx)
    caption = (
        "Episode return on nine DMC tasks at the frame budget (experiment 'main'): the paper's Table 1 "
        "(mean ± std over 6 seeds) beside the reproduced runs."
    )
    notes = []
    if not any(c.stats.n for c in cells if c.keys["method"] in ("DreamerV3", "TD-MPC", "A-LIX", "DrQ", "CURL")):
        notes.append("Baselines without runs (A-LIX, DrQ, CURL, DreamerV3, TD-MPC here) show the paper's value only.")
    table = comparison_table(ctx, "T1", cells, caption, notes, digits=0)
    return ArtifactResult(
        "T1", "Online DMC at 1M", caption, tables=[table], notes=table.notes, has_runs=has_data(cells)
    )
