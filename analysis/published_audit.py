"""The paper's DrQ-v2 baseline (Table 1) against the DrQ-v2 authors' published curves: the audit's rows of kind
``published`` (one per task, and the abstract's ratio recomputed with the published baseline), also read by the
report's calibration section (repro_app/report.py) and tests/test_calibration.py. A comparison with outside data,
never counted among the mismatches of the paper's own numbers."""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.calibration import SOURCE_TEXT, packaged_published, published_values
from analysis.findings import Finding, pm_text, result_text
from analysis.load import Results
from analysis.paper import DMC9, PaperData
from analysis.stats import DEFAULT_SEED, mean_cis, ratio_to_task_means

PUBLISHED_FRAME = 1_000_000  # Table 1's budget
# Bootstrap repetitions of the published-baseline rows (fewer than rliable's 50,000 so that `repro audit` stays
# a few seconds: the 9-task ratio resamples ten arrays per repetition).
PUBLISHED_REPS = 10_000


def published_baseline(p: PaperData, published: Results | None = None, reps: int = PUBLISHED_REPS,
                       seed: int = DEFAULT_SEED) -> list[Finding]:
    """The paper's DrQ-v2 cells of Table 1 against the published DrQ-v2 curves at 1M frames (one row per
    task: inside or outside the 95% CI of the published mean, by how much), and the abstract's TACO / DrQ-v2
    ratio recomputed with the published baseline beside Table 1's own."""
    published = packaged_published() if published is None else published
    t1 = p.online.set_index(["task", "method"])
    vals = {t: published_values(published, t, PUBLISHED_FRAME) for t in DMC9}
    cis = dict(zip(DMC9, mean_cis([vals[t] for t in DMC9], reps=reps, seed=seed)))
    out = []
    where = "T1 DrQ-v2 vs published curves"
    for t in DMC9:
        paper_mean, paper_std = float(t1.loc[(t, "DrQ-v2"), "mean"]), float(t1.loc[(t, "DrQ-v2"), "std"])
        v = vals[t]
        if len(v) == 0:
            out.append(Finding("drqv2_vs_published", where, f"{t}: no published DrQ-v2 curve reaching 1M frames",
                               pm_text(paper_mean, paper_std), "—", True, kind="published"))
            continue
        lo, hi = cis[t]
        pub = float(np.mean(v))
        inside = lo <= paper_mean <= hi
        gap = paper_mean - hi if paper_mean > hi else paper_mean - lo if paper_mean < lo else 0.0
        side = "inside" if inside else ("above" if gap > 0 else "below")
        text = (f"published {pub:.1f} [{lo:.1f}, {hi:.1f}] (n={len(v)}); paper {side} the CI"
                + ("" if inside else f" by {abs(gap):.1f}") + f"; paper − published mean {paper_mean - pub:+.1f} "
                f"({100 * (paper_mean / pub - 1):+.1f}%)")
        out.append(Finding("drqv2_vs_published", where,
                           f"{t}: Table 1's DrQ-v2 (1M) inside the 95% CI of the published mean at 1M",
                           pm_text(paper_mean, paper_std), text, inside, kind="published"))
    if all(len(vals[t]) for t in DMC9):
        piv = p.online.pivot(index="task", columns="method", values="mean").loc[list(DMC9)]
        taco = piv["TACO"].to_numpy(dtype=float).reshape(1, -1)
        paper_ratio = float(piv["TACO"].mean() / piv["DrQ-v2"].mean())
        r, lo, hi = ratio_to_task_means(taco, [vals[t] for t in DMC9], reps, seed)
        pub_mean = float(np.mean([np.mean(vals[t]) for t in DMC9]))
        out.append(Finding(
            "online_gain_vs_published", "abstract '1.4x' with the published DrQ-v2",
            "TACO / DrQ-v2 ratio of the 9-task means: Table 1's TACO over the published DrQ-v2 at 1M (9-task mean "
            f"{pub_mean:.1f}; Table 1's DrQ-v2: {piv['DrQ-v2'].mean():.1f}); the paper's own ratio inside its CI?",
            f"{paper_ratio:.3f}x (Table 1's own DrQ-v2)", f"{r:.3f}x (95% CI [{lo:.3f}, {hi:.3f}])",
            lo <= paper_ratio <= hi, kind="published"))
    return out


@functools.cache
def _published_baseline_of(root: Path) -> tuple[Finding, ...]:
    return tuple(published_baseline(PaperData(root)))


def check_published_baseline(p: PaperData) -> Iterable[Finding]:
    """:func:`published_baseline` of the packaged curves, computed once per process and paper folder (the
    bootstrap of the 9-task ratio takes seconds)."""
    return [replace(f) for f in _published_baseline_of(Path(p.root))]


def published_rows(findings: Iterable[Finding]) -> list[Finding]:
    """The findings that compare the paper's baseline with the published DrQ-v2 curves."""
    return [f for f in findings if f.kind == "published"]


def published_frame(findings: Iterable[Finding]) -> pd.DataFrame:
    """The display table of :func:`published_rows`."""
    rows = published_rows(findings)
    return pd.DataFrame({"Result": [result_text(f) for f in rows], "What": [f.description for f in rows],
                         "Paper prints": [f.printed for f in rows], "Published curves": [f.recomputed for f in rows]})


def published_summary(findings: Iterable[Finding]) -> str:
    """'3 of 9 of the paper's DrQ-v2 cells (Table 1, 1M) lie outside ...'."""
    cells = [f for f in published_rows(findings) if f.check == "drqv2_vs_published"]
    out = [f.description.split(":")[0] for f in cells if not f.match]
    names = f" ({', '.join(out)})" if out else ""
    return (f"{len(out)} of {len(cells)} of the paper's DrQ-v2 cells (Table 1, 1M frames) lie outside the 95% CI of "
            f"the published DrQ-v2 mean at 1M{names}; published: {SOURCE_TEXT}.")
