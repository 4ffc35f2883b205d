"""T3 (tab:offline_table): offline normalised scores, 4 tasks x 3 datasets x 7 methods, + average row."""

from __future__ import annotations

from analysis.context import Context
from analysis.offline_tables import offline_runs, t3_cells
from paper_figures.common import comparison_table, has_data
from paper_figures.registry import ArtifactResult, register


@register("T3", "Offline RL: normalised scores", "table", "tab:offline_table")
def render(ctx: Context) -> ArtifactResult:
    df = offline_runs(ctx.scores, ctx.experiment_map)
    cells = t3_cells(df, ctx.paper, ctx.reps, ctx.seed)
    caption = (
        "Offline normalised score at each run's own budget (its offline.updates): the normalized_score the run "
        "recorded at its last evaluation, 100 x return / the reference return it names (score_reference: "
        "'source', the best evaluation return of the online run that made the dataset; 'paper', the paper's "
        "Table 1 TACO return; the paper normalises by the best online TACO return). Average row: mean over "
        "the 12 task/dataset pairs of the runs' scores; the paper column is the average row as printed."
    )
    notes = []
    if not df.empty:
        refs = df[df["reached"].astype(bool)]["score_reference"].dropna().value_counts()
        if len(refs):
            notes.append("Normalised by: " + ", ".join(f"{k} ({v} runs)" for k, v in sorted(refs.items())))
    stats_note = (
        f"Reproduced: mean ± std over seeds (ddof=1) of runs that finished their offline.updates; 95% CI: "
        f"stratified bootstrap of the mean (rliable, {ctx.reps:,} repetitions, random state {ctx.seed}); "
        "Δ = reproduced − paper; n: finished runs (+k short: runs not finished, not used); — : no data.")
    table = comparison_table(ctx, "T3", cells, caption, notes, stats_note=stats_note)
    return ArtifactResult("T3", "Offline RL", caption, tables=[table], notes=table.notes, has_runs=has_data(cells))
