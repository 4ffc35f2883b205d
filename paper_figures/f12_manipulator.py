"""F12 (sfig:manipulator_online_rl): manipulator bring_ball learning curves over 30M frames."""

from __future__ import annotations

import pandas as pd

from analysis import select
from analysis.comparable import FRAMES, Budget, comparable, short_number
from analysis.context import Context
from analysis.robustness import SOLVED_RETURN, solved_counts
from analysis.tables import fmt_num, write_table
from paper_figures.curves import render_curves
from paper_figures.registry import ArtifactResult, register

TASK = "manipulator_bring_ball"
LABELS = ["TACO", "DrQ-v2"]
HORIZON = 30_000_000


@register("F12", "Manipulator bring_ball (30M frames)", "figure", "sfig:manipulator_online_rl")
def render(ctx: Context) -> ArtifactResult:
    curves = select.manipulator(ctx.curves, ctx.experiment_map)
    tasks = [TASK] + (sorted(set(curves["task"]) - {TASK}) if not curves.empty else [])
    caption = ("Evaluation return on manipulator bring_ball (experiment 'manipulator'); the paper trains for 30M "
               "frames and prints no numbers.")
    result = render_curves(ctx, "F12", "Manipulator Bring Ball", curves, tasks, LABELS, caption, "episode return",
                           per_seed=True, ncols=len(tasks), hline=(SOLVED_RETURN, "'solved' threshold"))
    solved = solved_counts(curves[curves["task"] == TASK] if not curves.empty else curves, HORIZON)
    paper = {"TACO": "3 of 6", "DrQ-v2": "0 of 6"}
    disp = []
    horizon = Budget(HORIZON, FRAMES, at_least=True)  # a run is compared with the paper once it reached 30M frames
    rows = curves[curves["task"] == TASK] if not curves.empty else curves
    for lab in LABELS:
        r = solved[solved["label"] == lab]
        mine = rows[rows["label"] == lab] if not rows.empty else rows
        lowest = float(mine.groupby("run_id")["frame"].max().min()) if not mine.empty else float("nan")
        text = "—" if r.empty else f"{int(r.iloc[0]['solved'])} of {int(r.iloc[0]['runs'])}"
        if not r.empty and not comparable(Budget(lowest, FRAMES), horizon):
            text += f" (runs reach only {short_number(lowest)} frames: not comparable)"
        disp.append(
            {
                "Method": lab,
                "Paper: seeds solved (30M env. frames)": paper[lab],
                "Reproduced: seeds solved": text,
                "Env. frames reached": "—" if r.empty else fmt_num(r.iloc[0]["last_frame"], 0),
            }
        )
    tcap = (
        f"Seeds that solve manipulator bring_ball within 30M frames: a seed counts as solved once an "
        f"evaluation return reaches {SOLVED_RETURN:g} (of 1000); the paper reports 3 of 6 for TACO and none for "
        "DrQ-v2. Counts of runs that stopped before 30M environment frames are not comparable with the paper's."
    )
    result.tables.append(write_table(ctx.out_dir, "F12", solved, tcap, pd.DataFrame(disp)))
    return result
