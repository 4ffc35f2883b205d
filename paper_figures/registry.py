"""The registry of paper artifacts (tables T1-T6, figures F1, F3-F13), keyed by id."""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from analysis.context import Context
from analysis.tables import TableOutput


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

# The modules that register artifacts (one per artifact; F7a and F7b are two).
ARTIFACT_MODULES = (
    "t1_online",
    "t2_repr_objectives",
    "t3_offline",
    "t4_speed",
    "t5_speed_taco",
    "t6_cql_alpha",
    "f1_average",
    "f3_action_repr",
    "f4_curves_dmc",
    "f5_curves_metaworld",
    "f6_tsne",
    "f7a_batch_size",
    "f7b_objectives",
    "f8_horizon",
    "f9_action_repeat",
    "f10_action_dim",
    "f11_seeds",
    "f12_manipulator",
    "f13_frames",
)


def load_artifacts() -> dict[str, Artifact]:
    """Import every artifact module (idempotent) so that :data:`REGISTRY` is complete."""
    import matplotlib

    matplotlib.use("Agg")
    for name in ARTIFACT_MODULES:
        importlib.import_module(f"paper_figures.{name}")
    return REGISTRY


class UnknownArtifactError(KeyError):
    """An artifact id that is not registered."""

    def __str__(self) -> str:
        return f"unknown artifact {self.args[0]!r} (known: {', '.join(ordered_ids())})"


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


def ordered_ids() -> list[str]:
    load_artifacts()
    return sorted(REGISTRY, key=_sort_key)


def resolve(ids: Iterable[str]) -> list[Artifact]:
    """Artifacts for ids (case-insensitive); ``F7`` means ``F7a`` and ``F7b``. Unknown ids raise."""
    load_artifacts()
    by_lower = {k.lower(): k for k in REGISTRY}
    out: list[str] = []
    for raw in ids:
        key = raw.strip().lower()
        if key in by_lower:
            matches = [by_lower[key]]
        else:
            matches = [k for k in ordered_ids() if re.fullmatch(re.escape(key) + r"[a-z]", k.lower())]
        if not matches:
            raise UnknownArtifactError(raw)
        out += [m for m in matches if m not in out]
    return [REGISTRY[k] for k in out]
