"""T6 (tab:cql_hyper): the CQL regulariser weight per task and dataset (a config, not a result)."""

from __future__ import annotations

import pandas as pd

from analysis.context import Context
from analysis.identity import task_display
from analysis.offline_tables import offline_runs
from analysis.tables import EMPTY, write_table
from paper_figures.registry import ArtifactResult, register


@register("T6", "CQL alpha per task/dataset", "table", "tab:cql_hyper")
def render(ctx: Context) -> ArtifactResult:
    paper = ctx.paper.cql_alpha
    runs = offline_runs(ctx.scores, ctx.experiment_map)
    cql = runs[runs["learner"] == "cql"] if not runs.empty else runs  # CQL and CQL+TACO
    raw, disp = [], []
    for r in paper.itertuples(index=False):
        rows = cql[(cql["task"] == r.task) & (cql["dataset"] == r.dataset)] if not cql.empty else cql
        used = sorted({float(a) for a in rows["cql_alpha"].dropna()}) if not rows.empty else []
        match = None if not used else (used == [float(r.alpha_cql)])
        raw.append({"task": r.task, "dataset": r.dataset, "paper_alpha": r.alpha_cql,
                    "runs_alpha": ";".join(f"{a:g}" for a in used), "runs": len(rows), "match": match})
        disp.append({"Task": task_display(r.task), "Dataset (paper's name)": f"{r.dataset} ({r.dataset_as_printed})",
                     "Paper α_CQL": f"{r.alpha_cql:g}", "α_CQL in runs": ", ".join(f"{a:g}" for a in used) or EMPTY,
                     "Runs": str(len(rows)), "Same": EMPTY if match is None else ("yes" if match else "no")})
    caption = ("α_CQL per task and dataset: the paper's Table 6 beside the alpha each CQL and CQL+TACO run of "
               "experiment 'offline' actually used (its resolved.json cql_alpha; — : no such runs).")
    notes = ["A hyperparameter table: there is no CI; 'Same' says whether every run used the paper's value.",
             "The paper's Table 6 names the full-replay dataset 'Replay'; it is matched to Table 3's 'Full-replay'."]
    table = write_table(ctx.out_dir, "T6", pd.DataFrame(raw), caption, pd.DataFrame(disp), notes)
    return ArtifactResult("T6", "CQL alpha", caption, tables=[table], notes=notes,
                          has_runs=any(r["runs_alpha"] for r in raw))
