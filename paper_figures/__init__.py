"""Every table (T1-T6) and figure (F1, F3-F13) of the TACO paper, rendered from run logs.

Importing the package registers every artifact module in :data:`paper_figures.registry.REGISTRY`
(the command line calls :func:`paper_figures.registry.load_artifacts` itself, so it does not depend on
this file being run).
"""

from paper_figures.registry import (
    REGISTRY,
    ArtifactResult,
    UnknownArtifactError,
    load_artifacts,
    ordered_ids,
    resolve,
)
from paper_figures.render import render_artifacts

load_artifacts()

__all__ = ["REGISTRY", "ArtifactResult", "UnknownArtifactError", "load_artifacts", "ordered_ids", "resolve",
           "render_artifacts"]
