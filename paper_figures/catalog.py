"""Every artifact of the paper, registered: imports each artifact module and looks artifacts up by id."""

from __future__ import annotations

import re
from collections.abc import Iterable

# Imported for their side effect: each artifact module registers its artifacts (one per module; F7a and F7b are two;
# T3b is derived from T3). common comes first: it selects the Agg backend before any figure module imports pyplot.
from paper_figures import (  # noqa: F401
    common,
    f1_average,
    f3_action_repr,
    f4_curves_dmc,
    f5_curves_metaworld,
    f6_tsne,
    f7a_batch_size,
    f7b_objectives,
    f8_horizon,
    f9_action_repeat,
    f10_action_dim,
    f11_seeds,
    f12_manipulator,
    f13_frames,
    t1_online,
    t2_repr_objectives,
    t3_offline,
    t3b_offline_poi,
    t4_speed,
    t5_speed_taco,
    t6_cql_alpha,
)
from paper_figures.registry import REGISTRY, Artifact, UnknownArtifactError, sorted_ids

__all__ = ["resolve", "sorted_ids"]  # sorted_ids through the catalog: every artifact registered first


def resolve(ids: Iterable[str]) -> list[Artifact]:
    """Artifacts for ids (case-insensitive); ``F7`` means ``F7a`` and ``F7b``. Unknown ids raise."""
    by_lower = {k.lower(): k for k in REGISTRY}
    out: list[str] = []
    for raw in ids:
        key = raw.strip().lower()
        if key in by_lower:
            matches = [by_lower[key]]
        else:
            matches = [k for k in sorted_ids() if re.fullmatch(re.escape(key) + r"[a-z]", k.lower())]
        if not matches:
            raise UnknownArtifactError(raw)
        out += [m for m in matches if m not in out]
    return [REGISTRY[k] for k in out]
