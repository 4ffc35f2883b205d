"""A report's figures and tables, drawn from its model (analysis/report_model.py): every artifact, and `repro verify`'s
figure from the verdicts and runs the model holds."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from analysis.context import Context
from analysis.report_model import ReportModel
from paper_figures.registry import Artifact, ArtifactResult
from paper_figures.render import render_artifacts
from paper_figures.verify_plot import plot_verify


@dataclass(frozen=True)
class ReportFigures:
    """What :func:`draw_report` drew: each artifact's result and `repro verify`'s figure (PNG, PDF; none without
    verify runs)."""

    artifacts: list[ArtifactResult]
    verify: list[Path]


def draw_report(ctx: Context, model: ReportModel, artifacts: Sequence[Artifact],
                progress: Callable[[str], None] | None = None) -> ReportFigures:
    """``artifacts`` rendered into ``ctx.out_dir`` (:func:`paper_figures.render.render_artifacts`, with its manifest)
    and the verify figure drawn from ``model.verify`` (analysis is not asked for its rows again)."""
    drawn = render_artifacts(ctx, artifacts, progress)
    verify = plot_verify(ctx.results, model.verify, ctx.out_dir) if model.verify.rows else []
    return ReportFigures(drawn, verify)
