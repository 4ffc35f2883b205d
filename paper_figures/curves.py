"""One renderer for the learning-curve figures (F4, F5, F11, F12)."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter

from analysis.calibration import band_caption, published_band
from analysis.comparable import frames_axis_label, paper_env, paper_frames, reached, short_number
from analysis.context import Context
from analysis.identity import task_display
from paper_figures.common import (
    NO_RUNS_TEXT,
    PAPER_MARK,
    banner,
    curve_panel,
    frames_label,
    palette,
    panel_grid,
    placeholder,
    published_panel,
    save_figure,
)
from paper_figures.registry import ArtifactResult


def render_curves(
    ctx: Context,
    artifact_id: str,
    title: str,
    curves: pd.DataFrame,
    tasks: Sequence[str],
    labels: Sequence[str],
    caption: str,
    ylabel: str,
    per_seed: bool = False,
    paper_marks: dict[tuple[str, str], float] | None = None,
    ncols: int = 3,
    hline: tuple[float, str] | None = None,
    published: bool = False,
) -> ArtifactResult:
    """One panel per task; mean + 95% CI band per label (or per-seed lines); paper diamonds at 1M where the panel's
    runs reached it or it has none (:func:`_paper_marks`); with
    ``published`` (and ``ctx.published_band``) the DrQ-v2 authors' published mean and CI band on each task that
    has one, up to the panel's last run frame (1M frames on a panel without runs)."""
    paper_marks = paper_marks or {}
    extra = sorted(set(curves["label"]) - set(labels)) if not curves.empty else []
    labels = [*labels, *extra]
    colors = palette(labels)
    ncols = min(ncols, len(tasks))
    fig, axes = panel_grid(len(tasks), ncols=ncols, size=(4.0, 3.0) if len(tasks) > 1 else (6.5, 4.2))
    any_data = drew_published = False
    short_panels = []  # panels whose runs stop short of the paper's budget: no diamond there
    # each run's last evaluated frame (the scores' evidence; the curves' grid may stop below it)
    last_frames = ctx.scores.drop_duplicates("run_id").set_index("run_id")["last_frame"] \
        if paper_marks and not ctx.no_runs else None
    for ax, task in zip(axes, tasks):
        rows = curves[curves["task"] == task] if not curves.empty else curves
        if published and ctx.published_band:
            upto = float(rows["frame"].max()) if not rows.empty else 1e6
            drew_published |= published_panel(ax, published_band(ctx.published, task, upto, ctx.curve_reps, ctx.seed))
        if not rows.empty:
            any_data = True
            curve_panel(ax, rows, labels, colors, ctx.curve_reps, ctx.seed, per_seed=per_seed)
        if _paper_marks(ax, task, rows, {lab: v for (t, lab), v in paper_marks.items() if t == task}, colors,
                        last_frames):
            short_panels.append(task)
        ax.xaxis.set_major_formatter(FuncFormatter(frames_label))
        if hline is not None and not rows.empty:
            ax.axhline(hline[0], color="#555555", ls="--", lw=1, label=hline[1])
        ax.set_title(task_display(task), fontsize=10)
        ax.set_xlabel(frames_axis_label(rows["action_repeat"] if not rows.empty and "action_repeat" in rows.columns
                                        else [paper_env()["action_repeat"]]), fontsize=8)
        ax.set_ylabel(ylabel)
        if not rows.empty:
            ax.legend(fontsize=7, loc="upper left")
    if ctx.no_runs:
        banner(fig, NO_RUNS_TEXT)
    elif not any_data:
        banner(fig, f"no runs for {artifact_id} under the results root")
    if len(tasks) > 1:
        fig.suptitle(title, y=1.04 if ctx.no_runs or not any_data else 1.0)
    fig.tight_layout()
    png = save_figure(fig, ctx, artifact_id)
    return ArtifactResult(artifact_id, title, _caption(ctx, caption, per_seed, bool(paper_marks), drew_published,
                                                       short_panels),
                          figures=[png], has_runs=any_data)


def _paper_marks(ax, task: str, rows: pd.DataFrame, marks: dict[str, float], colors: dict[str, str],
                 last_frames: pd.Series | None = None) -> bool:
    """The paper's values at its budget (diamonds at 1M frames) on a panel with no runs, or whose runs reached that
    budget (analysis.comparable.reached: a run's last evaluation at or past it), the one rule of what may stand
    beside the paper's values. A panel whose runs all stop short gets no diamond but a note in the panel, "runs at
    400 frames: the paper's 1M values are not comparable" (returns True then). A panel with neither runs nor marks
    gets a placeholder, one with marks only a legend of them. ``last_frames``: each run's last evaluated frame by
    run id (analysis.scores.final_scores' ``last_frame``); a run not in it is read from its curve."""
    paper = paper_frames()
    last = (rows.groupby("run_id")["frame"].max() if "run_id" in rows.columns else rows["frame"]) \
        if not rows.empty else pd.Series(dtype=float)
    if last_frames is not None and not last.empty and "run_id" in rows.columns:
        last = last_frames.reindex(last.index).fillna(last)
    short = bool(marks) and not rows.empty and not any(reached(f, paper.value) for f in last)
    if marks and not short:
        for lab, v in marks.items():
            ax.plot([paper.value], [v], **{**PAPER_MARK, "color": colors.get(lab, "black"), "markeredgecolor": "black"})
    if short:
        lo, hi = float(last.min()), float(last.max())
        at = short_number(hi) if lo == hi else f"{short_number(lo)}-{short_number(hi)}"
        ax.text(0.98, 0.03, f"runs at {at} frames: the paper's\n{paper.short()} values not comparable",
                transform=ax.transAxes, ha="right", va="bottom", fontsize=7, color="#b22222", style="italic",
                bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85, "pad": 1.5})
    if rows.empty and not marks:
        placeholder(ax, f"no runs for {task_display(task)}")
    elif rows.empty:
        ax.text(0.5, 0.95, "no runs", transform=ax.transAxes, ha="center", va="top", color="#777777")
        ax.set_xlim(0, 1.1e6)
        handles = [Line2D([], [], **{**PAPER_MARK, "color": colors.get(lab, "black"), "markeredgecolor": "black"},
                          label=f"{lab} (paper, 1M)") for lab in marks]
        handles += [h for h in ax.get_legend_handles_labels()[0] if isinstance(h, Line2D)]
        ax.legend(handles=handles, fontsize=7, loc="center left")
    return short


def _caption(ctx: Context, caption: str, per_seed: bool, paper_marks: bool, drew_published: bool,
             short_panels: Sequence[str] = ()) -> str:
    """The figure's caption: the artifact's own text, then what the lines, bands, diamonds and published band are."""
    bands = ("thin lines: individual seeds" if per_seed else
             f"lines: mean over seeds; bands: 95% stratified-bootstrap CI of the mean at each frame (rliable, "
             f"{ctx.curve_reps:,} repetitions, random state {ctx.seed}); curves are interpolated on a common "
             "frame grid and not extrapolated past a run's last evaluation")
    bands += ("; x axis: environment frames = agent steps x action repeat (the repeat in the axis label); a legend "
              "entry names how its runs' environment differs from the paper's, where it does")
    marks_text = " Diamonds at 1M frames: the paper's Table 1 values." if paper_marks else ""
    if paper_marks and short_panels:
        marks_text += (" They are drawn only on a panel whose runs reached 1M environment frames (or that has none): "
                       f"the runs of {', '.join(task_display(t) for t in short_panels)} stop short, their values "
                       "are not comparable with the paper's and the panel says so.")
    pub_text = " " + band_caption(ctx.curve_reps, ctx.seed) if drew_published else ""
    return f"{caption} {bands[0].upper() + bands[1:]}.{marks_text}{pub_text}"
