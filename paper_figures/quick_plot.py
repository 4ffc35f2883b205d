"""Learning curves of any set of runs (`repro plot`): one panel per task, one line per group, mean over seeds
with a 95% bootstrap CI band (rliable, fixed random state), written as PNG and PDF."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from analysis.calibration import band_caption  # noqa: E402
from analysis.comparable import env_differences, frames_axis_label  # noqa: E402
from analysis.identity import task_display  # noqa: E402
from analysis.io import atomic_savefig  # noqa: E402
from paper_figures.common import (  # noqa: E402
    PUBLISHED_STYLE,
    curve_panel,
    palette,
    panel_grid,
    published_panel,
    setup_style,
)

PLOT_REPS = 2_000  # bootstrap repetitions per plotted point (a quick look, not a paper table)


def plot_curves(curves: pd.DataFrame, metric: str, out: Path, x: str = "frame", by: Sequence[str] = ("method",),
                reps: int = PLOT_REPS, seed: int = 0,
                published: Mapping[str, pd.DataFrame] | None = None) -> list[Path]:
    """Write ``out`` (.png) and its .pdf sibling from tidy ``curves``: columns task, seed, label, ``x``, value.

    A run with a single evaluation shows as a point; a group with one seed has no CI band. ``published`` maps a
    task to the DrQ-v2 authors' published band (analysis.calibration.published_band), drawn grey and dashed
    on that task's panel."""
    if curves.empty:
        raise ValueError(f"no values of '{metric}' in the selected runs")
    setup_style()
    tasks = sorted(curves["task"].astype(str).unique())
    labels = sorted(curves["label"].unique())
    colors = palette(labels)
    fig, axes = panel_grid(len(tasks), ncols=min(3, len(tasks)))
    drew_published: list[str] = []
    for ax, task in zip(axes, tasks):
        rows = curves[curves["task"].astype(str) == task].rename(columns={x: "frame"})
        band = (published or {}).get(task)
        if band is not None and published_panel(ax, band):
            drew_published.append(task)
        curve_panel(ax, rows, labels, colors, reps=reps, seed=seed)
        for lab in labels:  # single evaluations still show up
            one = rows[rows["label"] == lab]
            if not one.empty and one["frame"].nunique() == 1:
                ax.scatter(one["frame"], one["value"], color=colors[lab], s=12)
        ax.set_title(task_display(task))
        ax.set_xlabel(frames_axis_label(rows.get("action_repeat", ())) if x == "frame" else x)
        ax.set_ylabel(metric)
    # One legend for all panels (the first panel may lack a group): label and its seed count(s) over tasks.
    seeds = curves.groupby(["label", "task"])["seed"].nunique()
    handles = [Line2D([], [], color=colors[lab], lw=1.6) for lab in labels]
    names = []
    for lab in labels:
        n = sorted(set(seeds.loc[lab].tolist()))
        runs = curves[curves["label"] == lab]
        env = env_differences(runs.drop_duplicates("run_id")) if "run_id" in runs.columns else ""
        seeds_text = f"n={n[0]}" if len(n) == 1 else f"n={n[0]}-{n[-1]}"
        names.append(f"{lab} ({seeds_text}{'; ' + env if env else ''})")
    if drew_published:
        handles.append(Line2D([], [], **PUBLISHED_STYLE))
        names.append("DrQ-v2 (published by its authors)")
    fig.legend(handles, names, loc="lower center", ncol=min(4, len(names)), frameon=False,
               bbox_to_anchor=(0.5, -0.02))
    caption = (f"{metric}: mean over seeds; band: 95% bootstrap CI of the mean (rliable, {reps:,} "
               f"repetitions, random state {seed}); n = seeds; grouped by {', '.join(by)}")
    if drew_published:
        caption += f". On {', '.join(drew_published)}: " + band_caption(reps, seed)
    fig.text(0.5, 1.0, textwrap.fill(caption, 60 * min(3, len(tasks))), ha="center", va="bottom", fontsize=8)
    fig.tight_layout(rect=(0, 0.06, 1, 0.98))
    out = Path(out).with_suffix(".png")
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        atomic_savefig(fig, out, dpi=150, bbox_inches="tight")
        atomic_savefig(fig, out.with_suffix(".pdf"), bbox_inches="tight")
    finally:
        plt.close(fig)
    return [out, out.with_suffix(".pdf")]
