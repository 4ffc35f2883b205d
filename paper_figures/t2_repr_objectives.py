"""T2 (tab:spr_table): TACO against SPR, ATC and DRIML objectives on the DrQ-v2 backbone."""

from __future__ import annotations

from analysis import select
from analysis.compare import build_cells
from analysis.context import Context
from paper_figures.common import comparison_table, has_data, relabel
from paper_figures.registry import ArtifactResult, register


@register("T2", "Representation objectives on DrQ-v2", "table", "tab:spr_table")
def render(ctx: Context) -> ArtifactResult:
    paper = ctx.paper.repr_objectives
    df = relabel(select.repr_objectives(ctx.scores, ctx.experiment_map), "method")
    expected = [{"task": t, "method": m} for t, m in zip(paper["task"], paper["method"])]

    def note(key: dict, rows) -> str:
        parts = []
        if key["method"] == "DRIML" and ctx.paper.repr_value(key["task"], "DRIML") is None:
            parts.append("paper: N/A (K=1 task, DRIML = TACO)")
        if not rows.empty and set(rows["experiment"]) - {"repr_objectives"}:
            parts.append("runs from " + ", ".join(sorted(set(rows["experiment"]))))
        return "; ".join(parts)

    cells = build_cells(
        df, ["task", "method"], expected,
        paper=lambda k: ctx.paper.repr_value(k["task"], k["method"]),
        reps=ctx.reps, seed=ctx.seed, note=note,
    )
    caption = (
        f"Return at the frame budget of TACO and other representation objectives ({', '.join(ctx.paper.repr_others)}), "
        "all on the DrQ-v2 backbone with action encoding (experiment 'repr_objectives'; TACO and DrQ-v2 fall back "
        "to 'main' runs where the sweep has none)."
    )
    table = comparison_table(ctx, "T2", cells, caption, digits=0)
    return ArtifactResult(
        "T2", "Representation objectives", caption, tables=[table], notes=table.notes, has_runs=has_data(cells)
    )
