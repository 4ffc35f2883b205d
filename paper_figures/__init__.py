"""Every table (T1-T6) and figure (F1, F3-F13) of the TACO paper, rendered from run logs.

Importing the package (or :mod:`paper_figures.catalog`) registers every artifact module in
:data:`paper_figures.registry.REGISTRY`.
"""

from paper_figures.catalog import resolve, sorted_ids
from paper_figures.registry import REGISTRY, ArtifactResult, UnknownArtifactError
from paper_figures.render import render_artifacts

__all__ = ["REGISTRY", "ArtifactResult", "UnknownArtifactError", "render_artifacts", "resolve", "sorted_ids"]
