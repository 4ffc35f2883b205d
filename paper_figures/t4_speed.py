"""T4 (tab:time_efficiency): frames per second of each algorithm at its own batch size."""

from __future__ import annotations

from analysis.context import Context
from paper_figures.registry import ArtifactResult, register
from paper_figures.speed_table import render_speed

WANTED = [("TACO", 1024), ("DrQ-v2", 256), ("A-LIX", 256), ("DrQ", 512), ("CURL", 512), ("DreamerV3", 256),
          ("TD-MPC", 256)]


@register("T4", "Speed of each algorithm (FPS)", "table", "tab:time_efficiency")
def render(ctx: Context) -> ArtifactResult:
    caption = "Training frames per second (FPS) of each algorithm at the batch size of its original implementation."
    return render_speed(ctx, "T4", "Time efficiency", WANTED, caption)
