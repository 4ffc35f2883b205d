"""One recomputed number of the audit (:class:`Finding`) and how it is printed; shared by the audit's checks
(analysis/audit.py) and its published-baseline rows (analysis/published_audit.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass
class Finding:
    """One recomputed number: ``match`` False is a mismatch; ``kind`` "info" rows are context, not checks;
    ``kind`` "published" rows hold the paper's DrQ-v2 baseline against the DrQ-v2 authors' published curves
    (``match`` False: outside the published 95% CI), a comparison with outside data, not counted as mismatches
    of the paper's own numbers."""

    check: str
    where: str
    description: str
    printed: str
    recomputed: str
    match: bool
    kind: str = "check"


def agree(a: float | None, b: float | None, tol: float = 1e-9) -> bool:
    """Whether two printed numbers agree (both missing counts as agreeing)."""
    if a is None or b is None or (isinstance(a, float) and math.isnan(a)) or (isinstance(b, float) and math.isnan(b)):
        return (a is None or (isinstance(a, float) and math.isnan(a))) and (
            b is None or (isinstance(b, float) and math.isnan(b))
        )
    return abs(float(a) - float(b)) <= tol


def pm_text(mean: Any, std: Any) -> str:
    """``mean ± std`` as printed (``N/A`` when there is no mean)."""
    if mean is None or (isinstance(mean, float) and math.isnan(mean)):
        return "N/A"
    return (
        f"{mean:g} ± {std:g}" if std is not None and not (isinstance(std, float) and math.isnan(std)) else f"{mean:g}"
    )


def result_text(f: Finding) -> str:
    """The Result column of a finding."""
    if f.kind == "published":
        return "inside published CI" if f.match else "OUTSIDE published CI"
    return "MISMATCH" if (f.kind == "check" and not f.match) else ("ok" if f.kind == "check" else "info")
