"""T5 (tab:time_efficiency_taco): frames per second of TACO by batch size."""

from __future__ import annotations

from analysis.context import Context
from paper_figures.registry import ArtifactResult, register
from paper_figures.speed_table import render_speed

WANTED = [("TACO", 1024), ("TACO", 512), ("TACO", 256)]


@register("T5", "Speed of TACO by batch size (FPS)", "table", "tab:time_efficiency_taco")
def render(ctx: Context) -> ArtifactResult:
    caption = "Training frames per second (FPS) of TACO at batch sizes 1024, 512 and 256."
    return render_speed(ctx, "T5", "Time efficiency of TACO", WANTED, caption)
