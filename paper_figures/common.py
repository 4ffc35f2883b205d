"""Plotting and table helpers shared by the artifact modules."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import seaborn as sns  # noqa: E402
from matplotlib.artist import Artist  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from analysis.comparable import env_differences, env_label  # noqa: E402
from analysis.context import Context  # noqa: E402
from analysis.identity import task_display  # noqa: E402
from analysis.io import save_figure_files  # noqa: E402
from analysis.stats import mean_cis  # noqa: E402
from analysis.tables import Cell, TableOutput, budget_notes, comparison_frames, write_table  # noqa: E402

METHOD_COLORS = {
    "TACO": "#d62728",
    "DrQ-v2": "#1f77b4",
    "A-LIX": "#2ca02c",
    "DrQ": "#9467bd",
    "CURL": "#8c564b",
    "DreamerV3": "#e377c2",
    "TD-MPC": "#7f7f7f",
    "SPR": "#bcbd22",
    "ATC": "#17becf",
    "DRIML": "#ff7f0e",
    "TACO w/o action repr": "#ff9896",
}
PAPER_MARK: dict[str, Any] = dict(marker="D", color="black", markersize=6, linestyle="none", zorder=5)
APART_HATCH = "////"  # a bar whose value is not comparable with the paper's (analysis.comparable)
NO_RUNS_TEXT = "no runs found: paper values only"


def setup_style() -> None:
    sns.set_theme(context="notebook", style="whitegrid", font_scale=0.95)
    # axes.titley: each title at the top of its axes (plus axes.titlepad), as placed when nothing is drawn above
    # the axes. Left unset, matplotlib measures every title against its axes' top-side ticks and the y axis's
    # offset text at every draw (a figure is laid out four or five times: tight_layout where used, a measuring and
    # a drawing pass per file): about 1 s of a first report (docs/performance.md). No figure here draws ticks or
    # labels on top; a y axis with an offset text (values past 1e6, below 1e-5, or in a narrow range) would draw it
    # under a title wide enough to reach the axes' left edge instead of pushing the title up.
    plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 150, "axes.titleweight": "bold", "axes.titley": 1.0})


def palette(labels: Sequence[str]) -> dict[str, str]:
    """A stable colour per label: the paper methods' fixed colours, then seaborn's palette."""
    others = [lab for lab in labels if lab not in METHOD_COLORS]
    extra = dict(zip(others, sns.color_palette("Set2", max(len(others), 1)).as_hex()))
    return {lab: METHOD_COLORS.get(lab, extra.get(lab, "#333333")) for lab in labels}


def save_figure(fig: plt.Figure, ctx: Context, name: str) -> Path:
    """Write ``{name}.png`` and ``{name}.pdf`` atomically (not again when the figure and its files are unchanged:
    :func:`analysis.io.save_figure_files`) and close the figure; returns the PNG path."""
    png = save_figure_files(fig, [ctx.out_dir / f"{name}.png", ctx.out_dir / f"{name}.pdf"], bbox_inches="tight")[0]
    plt.close(fig)
    return png


def env_banner(fig: plt.Figure, rows: pd.DataFrame, varied: Sequence[str] = ()) -> str:
    """Across the top of a figure (where :func:`banner` says that no runs were found: never both), how the
    environment of the runs drawn (``rows``, one or more per run) differs from the paper's
    (analysis.comparable.env_label); nothing when it does not. Returns the text."""
    runs = rows.drop_duplicates("run_id") if not rows.empty and "run_id" in rows.columns else rows
    text = env_label(runs, varied)
    if text:
        banner(fig, textwrap.fill(text, 140))
    return text


def banner(fig: plt.Figure, text: str) -> None:
    """A visible note across the top of a figure (e.g. that no runs were found)."""
    fig.text(0.5, 1.0, text, ha="center", va="bottom", fontsize=10, color="#b22222", style="italic")


def placeholder(ax: plt.Axes, text: str) -> None:
    """Mark an axis as having no data, with the reason."""
    ax.text(0.5, 0.5, textwrap.fill(text, 45), ha="center", va="center", transform=ax.transAxes, fontsize=9,
            color="#555555")
    ax.set_xticks([])
    ax.set_yticks([])


def bar_caption(ctx: Context, extra: str = "") -> str:
    return (
        f"Bars: reproduced mean over seeds at {ctx.budget_text()}; error bars: 95% stratified-bootstrap CI of "
        f"the mean (rliable percentile bootstrap, {ctx.reps:,} repetitions, random state {ctx.seed}); "
        "black diamonds: the paper's reported value (where the paper gives one); n: seeds that reached the "
        "budget; 'no runs' marks an empty cell; a hatched, pale bar is at another budget than the paper's value "
        "(its budget above it): not comparable with the diamond." + (" " + extra if extra else "")
    )


def grouped_bars(
    ax: plt.Axes,
    cf: pd.DataFrame,
    x: str,
    hue: str,
    x_order: Sequence,
    hue_order: Sequence[str],
    x_labels: Sequence[str] | None = None,
    colors: dict[str, str] | None = None,
) -> None:
    """Bars of reproduced means with 95% CI error bars, paper diamonds, n labels and empty-cell marks.

    ``cf`` is :func:`analysis.compare.cells_frame` output with columns ``x``, ``hue``, paper, n,
    mean, ci_low, ci_high.
    """
    colors = colors or palette(list(hue_order))
    n_h = max(len(hue_order), 1)
    width = 0.8 / n_h
    apart_at: set[str] = set()  # the budgets of bars not comparable with the paper's values
    top = (
        np.nanmax(
            np.r_[
                cf["ci_high"].to_numpy(dtype=float),
                cf["mean"].to_numpy(dtype=float),
                cf["paper"].to_numpy(dtype=float),
                1.0,
            ]
        )
        if not cf.empty
        else 1.0
    )
    for i, xv in enumerate(x_order):
        for j, hv in enumerate(hue_order):
            pos = i - 0.4 + width * (j + 0.5)
            row = cf[(cf[x] == xv) & (cf[hue] == hv)]
            if row.empty:
                continue
            r = row.iloc[0]
            apart = not bool(r.get("comparable", True))
            if r["n"] > 0 and not math.isnan(r["mean"]):
                if apart:
                    apart_at.add(str(r.get("budget") or "another budget"))
                err = None
                if not math.isnan(r["ci_low"]):
                    err = [[r["mean"] - r["ci_low"]], [r["ci_high"] - r["mean"]]]
                style: dict[str, Any] = dict(hatch=APART_HATCH, alpha=0.45, edgecolor="#333333") if apart else {}
                ax.bar(pos, r["mean"], width * 0.92, color=colors[hv], yerr=err, capsize=2, ecolor="#222222", zorder=3,
                       **style)
                label = f"n={int(r['n'])}" + (f", {r['budget']}" if apart and r.get("budget") else "")
                ax.text(pos, (r["ci_high"] if not math.isnan(r["ci_high"]) else r["mean"]) + 0.015 * top,
                        label, ha="center", va="bottom", fontsize=6.5, rotation=90)
            else:
                short = int(r.get("n_short", 0) or 0)
                empty = f"no runs ({short} short, at {r['short_at']})" if short and r.get("short_at") else "no runs"
                ax.text(pos, 0.01 * top, empty, ha="center", va="bottom", fontsize=6.5, rotation=90, color="#777777")
            if not math.isnan(r["paper"]):
                ax.plot([pos], [r["paper"]], **PAPER_MARK)
    ax.set_xticks(range(len(x_order)))
    ax.set_xticklabels(list(x_labels) if x_labels is not None else [str(v) for v in x_order])
    ax.set_xlim(-0.6, len(x_order) - 0.4)
    ax.set_ylim(0, top * 1.15)
    handles: list[Artist] = [Patch(color=colors[h], label=str(h)) for h in hue_order]
    handles.append(Line2D([], [], label="paper (reported)", **PAPER_MARK))
    if apart_at:
        handles.append(Patch(facecolor="white", edgecolor="#333333", hatch=APART_HATCH,
                             label=f"at {', '.join(sorted(apart_at))}: not comparable with the paper"))
    ax.legend(handles=handles, fontsize=7.5, loc="upper left", bbox_to_anchor=(1.0, 1.0))


def comparison_table(
    ctx: Context,
    name: str,
    cells: Sequence[Cell],
    caption: str,
    notes: Sequence[str] = (),
    digits: int = 1,
    hide: Sequence[str] = (),
    stats_note: str | None = None,
) -> TableOutput:
    """Write a comparison table (paper beside reproduced, n, CI, difference, paper-in-CI).

    ``hide`` drops display columns (e.g. a constant key); ``stats_note`` replaces the standard note on
    what the reproduced columns are.
    """
    raw, display = comparison_frames(cells, digits)
    display = display.drop(columns=[c for c in hide if c in display.columns])
    if "Task" in display.columns:
        display["Task"] = display["Task"].map(lambda t: task_display(t) if t != "Average" else t)
    full_notes = list(notes) + budget_notes(cells) + [stats_note or (
        f"Reproduced: mean ± std over seeds (std with ddof=1) at {ctx.budget_text()}; 95% CI: stratified "
        f"bootstrap of the mean (rliable, {ctx.reps:,} repetitions, random state {ctx.seed}); Δ = reproduced − "
        "paper (only where comparable); n: seeds that reached the budget (+k short: runs that stopped earlier, "
        "where they stopped; not used); — : no data."
    )]
    if ctx.no_runs:
        full_notes.insert(0, "No runs were found under the results root: only the paper's values are shown.")
    return write_table(ctx.out_dir, name, raw, caption, display, full_notes)


def curve_panel(
    ax: plt.Axes,
    curves: pd.DataFrame,
    labels: Sequence[str],
    colors: dict[str, str],
    reps: int,
    seed: int,
    per_seed: bool = False,
) -> None:
    """Mean learning curve with a 95% bootstrap CI band per label (or one thin line per seed)."""
    for lab in labels:
        rows = curves[curves["label"] == lab]
        if rows.empty:
            continue
        n_seeds = rows["seed"].nunique()
        runs = rows.drop_duplicates("run_id") if "run_id" in rows.columns else rows.iloc[0:0]
        env = env_differences(runs)
        if per_seed:
            for i, (_, s) in enumerate(rows.groupby("seed")):
                s = s.sort_values("frame")
                ax.plot(s["frame"], s["value"], color=colors[lab], lw=0.9, alpha=0.75,
                        label=f"{lab} (per seed, n={n_seeds}{'; ' + env if env else ''})" if i == 0 else None)
            continue
        pivot = rows.pivot_table(index="frame", columns="seed", values="value")
        frames = pivot.index.to_numpy(dtype=float)
        mean = pivot.mean(axis=1).to_numpy()
        cis = mean_cis([pivot.loc[f].to_numpy() for f in pivot.index], reps=reps, seed=seed)
        lo = np.array([c[0] for c in cis])
        hi = np.array([c[1] for c in cis])
        ax.plot(frames, mean, color=colors[lab], lw=1.6, label=f"{lab} (n={n_seeds}{'; ' + env if env else ''})")
        ax.fill_between(frames, lo, hi, color=colors[lab], alpha=0.2, lw=0)
    ax.xaxis.set_major_formatter(FuncFormatter(frames_label))


PUBLISHED_STYLE: dict[str, Any] = dict(color="#555555", ls="--", lw=1.3)
PUBLISHED_BAND_ALPHA = 0.15


def published_panel(ax: plt.Axes, band: pd.DataFrame) -> bool:
    """Draw the published DrQ-v2 mean (grey dashed) and its 95% CI band (analysis.calibration.published_band)
    on ``ax``; False when there is nothing to draw."""
    if band.empty:
        return False
    n = sorted(set(int(v) for v in band["n"]))
    n_text = str(n[0]) if len(n) == 1 else f"{n[0]}-{n[-1]}"
    ax.plot(band["frame"], band["mean"], **PUBLISHED_STYLE, label=f"DrQ-v2 (published, n={n_text})", zorder=2)
    ax.fill_between(band["frame"], band["ci_low"], band["ci_high"], color=PUBLISHED_STYLE["color"],
                    alpha=PUBLISHED_BAND_ALPHA, lw=0, zorder=1)
    return True


def frames_label(value: float, _pos: object = None) -> str:
    """Axis label of a frame count: 0, 20k, 1.5M."""
    if abs(value) < 1000:
        return f"{value:g}"
    return f"{value / 1e6:g}M" if abs(value) >= 1e6 else f"{value / 1e3:g}k"


def panel_grid(n: int, ncols: int = 3, size: tuple[float, float] = (4.0, 3.0)) -> tuple[plt.Figure, list[plt.Axes]]:
    nrows = max(1, math.ceil(n / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(size[0] * ncols, size[1] * nrows), squeeze=False)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def relabel(df: pd.DataFrame, name: str) -> pd.DataFrame:
    """Make the selection's ``label`` column the key column ``name`` (replacing any column of that name)."""
    if "label" not in df.columns:
        return df.assign(**{name: pd.Series(dtype=object)})
    return df.drop(columns=[name], errors="ignore").rename(columns={"label": name})


def has_data(cells: Sequence[Cell]) -> bool:
    return any(c.stats.n > 0 or c.n_short > 0 for c in cells)
