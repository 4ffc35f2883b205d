"""Render a list of artifacts into the output folder and write a manifest."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence

from analysis.context import Context
from analysis.io import atomic_write_text
from paper_figures.common import setup_style
from paper_figures.registry import Artifact, ArtifactResult


def render_artifacts(
    ctx: Context, artifacts: Sequence[Artifact], progress: Callable[[str], None] | None = None
) -> list[ArtifactResult]:
    """Render each artifact (in order) and write ``manifest.json`` listing the files of this call."""
    setup_style()
    ctx.out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for art in artifacts:
        if progress:
            progress(art.id)
        results.append(art.render(ctx))
    manifest = [
        {
            "id": r.id,
            "title": r.title,
            "has_runs": r.has_runs,
            "figures": [str(p.name) for p in r.figures],
            "tables": [str(f.name) for t in r.tables for f in t.files],
            "notes": r.notes,
        }
        for r in results
    ]
    atomic_write_text(ctx.out_dir / "manifest.json", json.dumps(manifest, indent=2) + "\n")
    return results
