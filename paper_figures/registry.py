"""The registry of paper artifacts (tables T1-T6, figures F1, F3-F13, and T3b derived from T3), keyed by id.

Each artifact module registers itself with :func:`register`; :mod:`paper_figures.catalog` imports them
all and looks artifacts up, so this module imports none of them.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from analysis.context import Context
from analysis.tables import TableOutput
from repro.config.errors import UserError


@dataclass
class ArtifactResult:
    """What rendering one artifact produced.

    ``figures`` are PNG paths (each with a PDF beside it); ``tables`` the written tables; ``notes``
    what the reader must know (missing runs, substitutions); ``extra`` numbers that claims reuse.
    """

    id: str
    title: str
    caption: str
    figures: list[Path] = field(default_factory=list)
    tables: list[TableOutput] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    has_runs: bool = False
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Artifact:
    """One table or figure of the paper and the function that renders it."""

    id: str
    title: str
    kind: str  # "table" or "figure"
    paper_label: str
    render: Callable[[Context], ArtifactResult]


REGISTRY: dict[str, Artifact] = {}


class UnknownArtifactError(UserError, KeyError):
    """An artifact id that is not registered."""

    def __str__(self) -> str:
        return f"unknown artifact {self.args[0]!r} (known: {', '.join(sorted_ids())})"


def register(artifact_id: str, title: str, kind: str, paper_label: str):
    """Decorator registering ``render(ctx) -> ArtifactResult`` under ``artifact_id``."""

    def deco(fn: Callable[[Context], ArtifactResult]) -> Callable[[Context], ArtifactResult]:
        if artifact_id in REGISTRY:
            raise ValueError(f"artifact {artifact_id} registered twice")
        REGISTRY[artifact_id] = Artifact(artifact_id, title, kind, paper_label, fn)
        return fn

    return deco


def _sort_key(artifact_id: str) -> tuple:
    m = re.fullmatch(r"([A-Z])(\d+)([a-z]?)", artifact_id)
    if not m:
        return ("Z", 0, artifact_id)
    return ({"T": 0, "F": 1}.get(m.group(1), 2), int(m.group(2)), m.group(3))


def sorted_ids() -> list[str]:
    """The registered ids, tables first, in paper order (``paper_figures.catalog`` registers them all)."""
    return sorted(REGISTRY, key=_sort_key)
