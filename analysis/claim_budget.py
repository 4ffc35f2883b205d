"""At what budget, and with how many seeds, each claim of ``claims.csv`` may get a verdict.

The budgets are data (``analysis/claim_budgets.csv``, read from the paper and ARTIFACTS.md), never taken
from the runs: a claim made at 1M frames is judged at 1M frames whatever the runs reached.

Columns: ``id``; ``budget_kind`` — ``frames`` (environment frames, after action repeat), ``offline_updates``
(the run's own configured ``offline.updates``: the run is at budget when it finished) or ``none`` (a
timing, no training length); ``budget`` (frames, empty otherwise); ``min_seeds`` (seeds per cell before a
verdict; the paper's count is ``paper_seeds``); ``experiments`` (the canonical experiments the claim reads,
``;``-separated, used to say how far the runs got); ``holds`` / ``fails`` (wording of an indicative
reading; a number of the paper's prose in it is a ``{name}`` of claim_numbers.csv, filled in where it is shown:
analysis.claims.budget_words); ``source`` (where the budget comes from).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.select import ExperimentMap, expand_experiments

BUDGETS_CSV = Path(__file__).resolve().parent / "claim_budgets.csv"
KINDS = ("frames", "offline_updates", "none")


@dataclass(frozen=True)
class ClaimBudget:
    """One row of ``claim_budgets.csv``."""

    id: str
    kind: str
    budget: int | None
    min_seeds: int
    paper_seeds: int
    experiments: tuple[str, ...]
    holds: str
    fails: str
    source: str

    def text(self) -> str:
        """The budget as shown beside a verdict: '1M frames', 'own offline.updates', 'no training budget'."""
        if self.kind == "frames" and self.budget is not None:
            return frames_text(self.budget)
        return "each run's offline.updates" if self.kind == "offline_updates" else "no training budget"

    def column(self, runs: pd.DataFrame) -> str:
        """The budget in the claims table's Budget column, with its unit and, for frames, the action repeat beside
        them: the repeats of the claim's ``runs`` (rows of final_scores), the paper's when there are none
        ('1M env. frames (action repeat 2)', '1M env. frames (action repeat 1, 2, 4)'); "each run's
        offline.updates (gradient updates)"; 'no training budget'."""
        from analysis.comparable import FRAMES, Budget, paper_env

        if self.kind == "frames" and self.budget is not None:
            repeats = runs["action_repeat"].dropna() if "action_repeat" in runs.columns and not runs.empty else ()
            if len(repeats) == 0:
                repeats = (paper_env()["action_repeat"],)
            return Budget(self.budget, FRAMES, tuple(sorted({int(r) for r in repeats}))).text()
        return "each run's offline.updates (gradient updates)" if self.kind == "offline_updates" else self.text()


def frames_text(frames: float) -> str:
    """1_000_000 -> '1M frames'; 400 -> '400 frames'."""
    return f"{frames / 1e6:g}M frames" if frames >= 1_000_000 else f"{int(frames):,} frames"


def load_budgets(path: Path = BUDGETS_CSV) -> dict[str, ClaimBudget]:
    """Every row of the budget table by claim id; raises ValueError on a malformed row."""
    df = pd.read_csv(path, dtype={"id": str}, keep_default_na=False)
    out: dict[str, ClaimBudget] = {}
    for row in df.itertuples(index=False):
        if row.budget_kind not in KINDS:
            raise ValueError(f"{path}: claim {row.id}: budget_kind {row.budget_kind!r} is not one of {KINDS}")
        budget = int(float(row.budget)) if str(row.budget).strip() else None
        if row.budget_kind == "frames" and (budget is None or budget <= 0):
            raise ValueError(f"{path}: claim {row.id}: a frames budget needs a positive 'budget'")
        if int(row.min_seeds) < 1:
            raise ValueError(f"{path}: claim {row.id}: min_seeds must be >= 1")
        out[row.id] = ClaimBudget(row.id, row.budget_kind, budget, int(row.min_seeds), int(row.paper_seeds),
                                  tuple(e for e in str(row.experiments).split(";") if e), str(row.holds),
                                  str(row.fails), str(row.source))
    return out


@dataclass(frozen=True)
class Reach:
    """How far the runs a claim reads got: number of runs, their last frames, finished runs."""

    runs: int
    lowest: float
    highest: float
    done: int

    def describe(self) -> str:
        if self.runs == 0:
            return "no runs"
        if self.lowest == self.highest:
            return f"runs reach {frames_text(self.highest)}"
        return f"runs reach {frames_text(self.lowest)} to {frames_text(self.highest)}"


def claim_runs(scores: pd.DataFrame, spec: ClaimBudget, experiment_map: ExperimentMap | None,
               offline: bool) -> pd.DataFrame:
    """Rows of ``scores`` (one per run) from the claim's experiments, offline runs only if ``offline``."""
    if scores.empty:
        return scores
    rows = scores[scores["experiment"].isin(expand_experiments(spec.experiments, experiment_map))]
    has_dataset = rows["dataset"].notna()
    return rows[has_dataset] if offline else rows[~has_dataset]


def other_experiments(scores: pd.DataFrame, read: Sequence[str], offline: bool) -> dict[str, int]:
    """Experiments with runs (online, or offline with ``offline``) other than those ``read``: name -> runs, in order
    of name."""
    if scores.empty:
        return {}
    rows = scores[~scores["experiment"].isin(list(read))]
    rows = rows[rows["dataset"].notna()] if offline else rows[rows["dataset"].isna()]
    return {str(k): int(v) for k, v in rows.groupby("experiment").size().sort_index().items()}


def map_hint(canonical: str, found: dict[str, int], offline: bool = False) -> str:
    """The `-x` option that reads the experiments ``found`` (name -> runs) as ``canonical`` (repro_app/analysis_cli.py
    --experiment-map), in words: "runs exist in experiment(s) tiny (8 online runs): `-x main=tiny` reads them as
    main"; '' when none were found."""
    if not found:
        return ""
    kind = "offline" if offline else "online"
    listed = ", ".join(f"{e} ({n} {kind} run{'s' if n != 1 else ''})" for e, n in found.items())
    return (f"runs exist in experiment(s) {listed}: `-x {canonical}={','.join(found)}` reads them as "
            f"experiment {canonical}")


def claim_hint(scores: pd.DataFrame, spec: ClaimBudget, experiment_map: ExperimentMap | None) -> str:
    """For a claim whose experiments have no runs: which other experiments have runs of its kind, and the `-x` that
    reads them as the claim's last (most general) experiment (``main``; ``offline`` for the offline claims)."""
    offline = spec.kind == "offline_updates"
    if not spec.experiments:
        return ""
    found = other_experiments(scores, expand_experiments(spec.experiments, experiment_map), offline)
    return map_hint(spec.experiments[-1], found, offline)


def unread_hints(scores: pd.DataFrame, experiment_map: ExperimentMap | None) -> list[str]:
    """Runs that no claim reads (experiments none of claim_budgets.csv's names, as mapped): the `-x` options that read
    the online ones as ``main`` and the offline ones as ``offline`` (:func:`map_hint`)."""
    canonical = list(dict.fromkeys(e for b in load_budgets().values() for e in b.experiments))
    read = expand_experiments(canonical, experiment_map)
    hints = [map_hint("main", other_experiments(scores, read, False)),
             map_hint("offline", other_experiments(scores, read, True), True)]
    return [h for h in hints if h]


def reach(runs: pd.DataFrame) -> Reach:
    """The :class:`Reach` of ``runs`` (rows of final_scores); runs without evaluations count as frame 0."""
    if runs.empty:
        return Reach(0, math.nan, math.nan, 0)
    last = pd.to_numeric(runs["last_frame"], errors="coerce").fillna(0.0)
    return Reach(len(runs), float(last.min()), float(last.max()), int((runs["status"] == "done").sum()))


def seed_counts(runs: pd.DataFrame) -> str:
    """Seeds per cell (runs of one experiment, variant, method, task and dataset) as '2 seeds' or '1-3 seeds'."""
    if runs.empty:
        return "0 seeds"
    n = runs.groupby(["experiment", "variant", "method", "task", "dataset"], dropna=False)["seed"].nunique()
    lo, hi = int(n.min()), int(n.max())
    return f"{lo} seed{'s' if lo != 1 else ''}" if lo == hi else f"{lo}-{hi} seeds"
