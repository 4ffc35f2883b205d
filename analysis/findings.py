"""One recomputed number of the audit (:class:`Finding`) and how it is printed; shared by the audit's checks
(analysis/audit.py) and its published-baseline rows (analysis/published_audit.py)."""

from __future__ import annotations

import math
from collections.abc import Iterable
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


# ---------------------------------------------------------------- the paper's printed precision
PRECISION_NOTE = ("Derived numbers are compared at the paper's printed precision: a printed value matches when some "
                  "value that prints as it (within half a unit of its last printed digit) lies in the range the "
                  "recomputation gives with every input anywhere within its own printed rounding; rounding is not a "
                  "mismatch (e.g. FPS 130 / 35 = 3.714, and 3.648-3.783 with each FPS within ±0.5, which includes "
                  "values printed 3.6).")


def places(values: Iterable[float]) -> int:
    """The decimals a column of printed numbers shows: the most any of them has (52.4 -> 1; 130 -> 0)."""
    out = 0
    for v in values:
        text = f"{float(v):.10g}"
        if "." in text and "e" not in text:
            out = max(out, len(text.split(".")[1]))
    return out


def half_unit(digits: int) -> float:
    """Half a unit of the last digit of a number printed with ``digits`` decimals (its rounding interval's radius)."""
    return 0.5 * 10.0 ** -digits


def printed_within(printed: float, digits: int, low: float, high: float) -> bool:
    """Whether a number printed as ``printed`` with ``digits`` decimals can be a value in [low, high]: its rounding
    interval (±:func:`half_unit`) meets that range."""
    h = half_unit(digits) * (1 + 1e-9)
    return low <= printed + h and high >= printed - h


def ratio_range(num: float, den: float, num_h: float, den_h: float) -> tuple[float, float]:
    """The range of num / den with the numerator within ±num_h and the (positive) denominator within ±den_h."""
    return (num - num_h) / (den + den_h), (num + num_h) / (den - den_h)


def rounding_text(low: float, high: float, inputs: str, digits: int, printed_as: float, point: float) -> str:
    """What :func:`printed_within` read: the range, and that the printed value is in it by rounding alone."""
    text = f"{low:.3f}-{high:.3f} with {inputs}"
    if round(point, digits) != round(printed_as, digits) and printed_within(printed_as, digits, low, high):
        text += f": includes values printed {printed_as:.{digits}f}, so rounding, not a mismatch"
    return text
