"""Shared renderer of the speed tables T4 and T5 (frames per second on the user's hardware)."""

from __future__ import annotations

import numpy as np

from analysis.context import Context
from analysis.speed import speed_measurements
from analysis.stats import CellStats, mean_cis, mean_std
from analysis.tables import Cell
from paper_figures.common import comparison_table
from paper_figures.registry import ArtifactResult


def speed_cells(ctx: Context, wanted: list[tuple[str, int]]) -> tuple[list[Cell], bool]:
    """Cells for (method, batch size) rows: paper FPS (A100) beside each measured hardware/source."""
    meas = speed_measurements(ctx.results)
    paper = ctx.paper.time_efficiency
    paper_fps = {(m, int(b)): float(f) for m, b, f in zip(paper["method"], paper["batch_size"], paper["fps"])}
    ref_paper = paper_fps.get(("TACO", 1024))
    groups: list[tuple[str, int, str, str, np.ndarray]] = []
    for method, batch in wanted:
        sel = meas[(meas["method"] == method) & (meas["batch_size"] == batch)]
        if sel.empty:
            groups.append((method, batch, "—", "—", np.array([])))
        for (hw, src), rows in sel.groupby(["hardware", "source"]):
            groups.append((method, batch, hw, src, rows["fps"].to_numpy(dtype=float)))
    cis = mean_cis([g[4] for g in groups], reps=ctx.reps, seed=ctx.seed)
    ref_measured = {}
    for method, batch, hw, src, vals in groups:
        if (method, batch) == ("TACO", 1024) and len(vals):
            ref_measured[(hw, src)] = float(np.mean(vals))
    cells = []
    for (method, batch, hw, src, vals), (lo, hi) in zip(groups, cis):
        n, mean, std = mean_std(vals)
        pf = paper_fps.get((method, batch))
        parts = []
        if pf is not None and ref_paper:
            parts.append(f"paper: {pf / ref_paper:.2f}x TACO B1024")
        ref = ref_measured.get((hw, src))
        if n and ref:
            parts.append(f"measured: {mean / ref:.2f}x TACO B1024")
        cells.append(Cell({"method": method, "B": batch, "hardware": hw, "source": src}, pf, None,
                          CellStats(n, mean, std, lo, hi), note="; ".join(parts)))
    return cells, bool(len(meas))


def render_speed(
    ctx: Context, artifact_id: str, title: str, wanted: list[tuple[str, int]], caption: str
) -> ArtifactResult:
    cells, any_meas = speed_cells(ctx, wanted)
    notes = [
        "The paper's FPS were measured on an NVIDIA A100; reproduced FPS are labelled with the hardware they "
        "were measured on, so compare the speed ratios (Note column) rather than absolute FPS, and read "
        "'Paper in CI' only for A100 measurements. Each run's FPS is the median over its training episodes "
        "after updates started; n counts runs or benchmark entries."
    ]
    if not any_meas:
        notes.insert(0, "No FPS measurements found (no runs with train.csv fps and no bench/*.json).")
    stats_note = (f"Reproduced: mean ± std (ddof=1) over runs or benchmark entries; 95% CI: bootstrap of the mean "
                  f"(rliable, {ctx.reps:,} repetitions, random state {ctx.seed}); Δ = reproduced − paper; — : no data.")
    table = comparison_table(ctx, artifact_id, cells, caption, notes, digits=1, stats_note=stats_note)
    return ArtifactResult(artifact_id, title, caption, tables=[table], notes=table.notes,
                          has_runs=any(c.stats.n for c in cells))
