"""One renderer for the bar figures (F3, F7a, F7b, F8, F9, F10): comparison table + grouped bars."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import matplotlib.pyplot as plt
import pandas as pd

from analysis.compare import build_cells, cells_frame
from analysis.context import Context
from paper_figures.common import (
    NO_RUNS_TEXT,
    banner,
    bar_caption,
    comparison_table,
    env_banner,
    grouped_bars,
    has_data,
    palette,
    save_figure,
)
from paper_figures.registry import ArtifactResult


def render_bars(
    ctx: Context,
    artifact_id: str,
    title: str,
    df: pd.DataFrame,
    x: str,
    hue: str,
    x_order: Sequence[Any],
    hue_order: Sequence[str],
    caption: str,
    ylabel: str,
    paper: Callable[[dict[str, Any]], tuple[float | None, float | None] | None] | None = None,
    x_labels: Callable[[Any], str] = str,
    notes: Sequence[str] = (),
    figsize: tuple[float, float] = (8.0, 4.0),
    colors: dict[str, str] | None = None,
    digits: int = 0,
    hide: Sequence[str] = (),
    varied: Sequence[str] = (),
) -> tuple[ArtifactResult, list]:
    """Build cells over ``x_order`` x ``hue_order`` (+ any extra groups in the data), write the table and figure.
    ``varied``: environment settings the figure itself varies (F9's action repeat), not labelled as differences
    from the paper's environment."""
    expected = [{x: xv, hue: hv} for xv in x_order for hv in hue_order]
    cells = build_cells(df, [x, hue], expected, paper=paper, reps=ctx.reps, seed=ctx.seed, varied=varied)
    xs = list(dict.fromkeys([*x_order, *(c.keys[x] for c in cells)]))
    hues = list(dict.fromkeys([*hue_order, *(c.keys[hue] for c in cells)]))
    table = comparison_table(ctx, artifact_id, cells, caption, notes, digits=digits, hide=hide)
    fig, ax = plt.subplots(figsize=figsize)
    grouped_bars(ax, cells_frame(cells), x, hue, xs, hues, x_labels=[x_labels(v) for v in xs],
                 colors=colors or palette(hues))
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if len(xs) > 4:
        ax.tick_params(axis="x", rotation=30)
    if ctx.no_runs:
        banner(fig, NO_RUNS_TEXT)
    env_banner(fig, df, varied)
    png = save_figure(fig, ctx, artifact_id)
    result = ArtifactResult(artifact_id, title, caption + " " + bar_caption(ctx), figures=[png], tables=[table],
                            notes=table.notes, has_runs=has_data(cells))
    return result, cells
