"""What every claim shares: the verdicts, a claim's spec (:class:`ClaimSpec`, :class:`Simulation`), what a rule
takes and gives (:data:`Draws`, :class:`Judgement`), the numbers a verdict prints, the means of the runs per cell, and
the budget rule by which each claim is read (its own budget and seed minimum, an indicative reading below them). The
claims themselves are in the family modules (analysis/claims/online.py, offline.py, ablations.py), the helpers of
rules over draws in analysis/claims/draws.py; analysis/claims/catalog.py lists and judges them."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from analysis import comparable, select
from analysis.cells import Cells, CellSource, Key, means_table, observed_cells
from analysis.claim_budget import ClaimBudget, claim_hint, claim_runs, frames_text, reach, seed_counts
from analysis.context import Context
from analysis.paper import PaperData

SUPPORTED, REFUTED, NO_DATA = "supported", "refuted", "not enough data"


@dataclass
class Verdict:
    """The outcome of one claim: verdict, the numbers behind it, the rule applied, the claim's budget and
    seed minimum, and (on request, only when ``verdict`` is "not enough data") an indicative reading."""

    id: str
    claim: str
    verdict: str
    evidence: str
    rule: str
    budget: str = ""
    min_seeds: int = 0
    indicative: str = ""

    @property
    def shown(self) -> str:
        """What a table shows in its Verdict column: the indicative label when there is one."""
        return self.indicative or self.verdict


class NotEnoughData(Exception):
    """Raised by a check or a rule when the cells it needs are missing or have too few seeds."""


Check = Callable[[Context], tuple[str, str]]  # a claim's check on the runs: (verdict, evidence)


# A text as written, or one built from the paper data (a rule or note that quotes a number the paper prints)
PaperText = str | Callable[[PaperData], str]


def paper_text(text: PaperText, paper: PaperData) -> str:
    """``text`` as shown for ``paper``: built from its numbers where it quotes them."""
    return text(paper) if callable(text) else text


# A claim's cells with a leading draws axis: cell -> (draws, seeds) values, the same seeds in every draw. The user's
# runs are one draw (analysis.claims.draws.one_draw); the power simulation's, thousands.
Draws = dict[Key, np.ndarray]


@dataclass(frozen=True)
class Judgement:
    """What a claim's rule gives on :data:`Draws`: the verdict of every draw (supported, refuted, or not enough data
    where that depends on the draw), and the evidence of draw 0 (its numbers, or why it is not enough data)."""

    verdicts: np.ndarray  # (draws,) of SUPPORTED / REFUTED / NO_DATA
    evidence: str

    @property
    def first(self) -> tuple[str, str]:
        """Draw 0 as a check gives it: (verdict, evidence); :class:`NotEnoughData` with the evidence where it is not
        enough data."""
        verdict = str(self.verdicts[0])
        if verdict == NO_DATA:
            raise NotEnoughData(self.evidence)
        return verdict, self.evidence


# A claim's rule given the numbers it reads from a context (the paper's, the claim's seed minimum and budget, the
# bootstrap of its CIs): what `repro claims` calls on the runs as one draw and the power simulation on all its draws.
Judge = Callable[[Context, Draws], Judgement]


@dataclass(frozen=True)
class Simulation:
    """How the power simulation (analysis/power.py) runs a claim: ``sources(ctx, budget)`` the claim's cells with
    where the paper gives each (analysis/cells.py), ``judge(ctx, draws)`` the claim's rule on every draw at once
    (:data:`Judge`: the one its check calls on the runs as one draw), ``observed(ctx)`` the same cells from the user's
    runs (None: not conditioned on runs), ``tasks`` those of its runs (what its seeds cost), ``sims`` the draws if
    fewer than the caller's, ``reps`` the bootstrap repetitions the rule runs in every draw (0: none)."""

    sources: Callable[[Context, float], list[CellSource]]
    judge: Judge
    observed: Callable[[Context], Cells] | None
    tasks: tuple[str, ...]
    sims: int | None = None
    reps: int = 0
    notes: tuple[PaperText, ...] = ()

    def notes_text(self, paper: PaperData) -> list[str]:
        """``notes`` as shown for ``paper`` (:func:`paper_text`)."""
        return [paper_text(n, paper) for n in self.notes]


@dataclass(frozen=True)
class ClaimSpec:
    """One claim, defined once (:data:`SPECS`) and read by `repro claims`, `repro plan --claims` and the report:
    its ``check`` on the runs with its one-line ``rule`` (where it quotes a number of the paper's prose, a function of
    the paper data: :meth:`rule_text`), and either its ``simulation`` (its cells from the runs and
    from the paper) or why the power simulation cannot run it (``not_simulated``). Its budget and seed minimum are
    the row of analysis/claim_budgets.csv with its id (a reading's: the claim it reads). A ``reading_of`` spec is
    another reading of that claim of claims.csv (its budget, its text with ``note`` appended), listed after it and
    not counted among the paper's claims."""

    id: str
    check: Check
    rule: PaperText
    simulation: Simulation | None = None
    not_simulated: str = ""
    reading_of: str = ""
    note: str = ""
    # the audit's checks (analysis/audit.py, Finding.check) whose finding bounds the truth the power simulation
    # assumes: where one does not match, the power table names it (analysis/power.py)
    audit: tuple[str, ...] = ()

    def rule_text(self, paper: PaperData) -> str:
        """``rule`` as shown for ``paper``, with the numbers it quotes from the paper data (:func:`paper_text`)."""
        return paper_text(self.rule, paper)

    @property
    def claim_id(self) -> str:
        """The id of the claim of claims.csv (and of its row of claim_budgets.csv) this spec judges."""
        return self.reading_of or self.id


def means(df: pd.DataFrame, keys: Sequence[str], value: str = "score") -> dict[tuple, tuple[int, float]]:
    """(n, mean) per key over the runs that reached the budget: the means of their cells (analysis.cells)."""
    return means_table(observed_cells(df, keys, value))


def get(ctx: Context, table: dict[tuple, tuple[int, float]], *key) -> float | None:
    """The mean of a cell with at least ``ctx.min_seeds`` seeds, else None."""
    n, mean = table.get(tuple(key), (0, math.nan))
    return mean if n >= ctx.min_seeds else None


def present(ctx: Context, table: dict[tuple, tuple[int, float]], *key) -> float:
    """``get`` of a cell already known to have enough seeds (checked by ``require`` or by a ``get``)."""
    value = get(ctx, table, *key)
    assert value is not None, key
    return value


def too_few_seeds(missing: Sequence[tuple], min_seeds: int, budget: str) -> NotEnoughData:
    """The one "not enough data" of cells that lack seeds: it names the first six of ``missing`` with the seeds they
    need (``min_seeds``) and the budget they must reach (in words). Raised by :func:`require` on a ``means`` table and
    by analysis.claims.draws.require_cells on draws."""
    shown = ", ".join("/".join(str(p) for p in k) for k in missing[:6])
    more = f" (+{len(missing) - 6} more)" if len(missing) > 6 else ""
    return NotEnoughData(f"need >= {min_seeds} seeds that reached {budget} for: {shown}{more}")


def require(ctx: Context, table: dict, keys: Sequence[tuple]) -> None:
    """:func:`too_few_seeds` of the cells of ``keys`` whose mean in ``table`` has fewer than ``ctx.min_seeds``."""
    missing = [k for k in keys if get(ctx, table, *k) is None]
    if missing:
        raise too_few_seeds(missing, ctx.min_seeds, ctx.budget_text())


def apart(values: Sequence[float], digits: int, most: int = 6) -> list[str]:
    """``values`` printed with ``digits`` decimals, or with more (up to ``most``) where two that differ would print
    the same: a comparison a verdict makes between them is then visible in the numbers it quotes (no "ahead" between
    "500.0" and "500.0")."""
    def clash(d: int) -> bool:
        shown = [f"{v:.{d}f}" for v in values]
        return any(shown[i] == shown[j] and values[i] != values[j]
                   for i in range(len(values)) for j in range(i + 1, len(values)))

    d = digits
    while d < most and clash(d):
        d += 1
    return [f"{v:.{d}f}" for v in values]


def vs_text(a: float, b: float, digits: int) -> str:
    """'a vs b' for a comparison a > b, the two printed apart (:func:`apart`); '(tie)' when they are equal."""
    x, y = apart([a, b], digits)
    return f"{x} vs {y}" + (" (tie)" if a == b else "")


def pct(a: float, b: float) -> str:
    """a over b in percent, with the decimals that tell it from 0 when a and b differ."""
    return f"{'+' if a >= b else ''}{apart([100 * (a / b - 1), 0.0], 1)[0]}%"


def frames_apart(frames: Sequence[float]) -> list[str]:
    """Frame counts as the claims quote them: '0.75M' from 10K frames on (two decimals, more where two that differ
    would print the same), '400 frames' below (an indicative reading of short runs: not '0.00M')."""
    if all(f >= 10_000 for f in frames):
        return [f"{m}M" for m in apart([f / 1e6 for f in frames], 2)]
    return [f"{int(f):,} frames" if f == int(f) else f"{f:,.1f} frames" for f in frames]


def labelled(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=["method"], errors="ignore").rename(columns={"label": "method"}) if "label" in df else df


def online_rows(ctx: Context) -> pd.DataFrame:
    """The runs of the main online experiment, with the label as the method (the rows of the Table 1 claims)."""
    return labelled(select.online_main(ctx.scores, ctx.experiment_map))


GAIN_TOLERANCE = 0.1  # online_avg_gain: how far short of the paper's "about 1.4x" the ratio may fall


def paper_gain(paper: PaperData) -> float:
    """online_avg_gain's "about 1.4x" as the paper's prose gives it (repro_data/paper/claim_numbers.csv)."""
    return paper.claim_number("online_avg_gain", "gain")


def gain_bar(paper: PaperData) -> float:
    """The ratio online_avg_gain needs: the paper's gain less :data:`GAIN_TOLERANCE` (1.4 - 0.1 = 1.3), rounded to
    6 decimals so that the subtraction's last bit (1.4 - 0.1 is 1.2999999999999998 in floats) moves no verdict."""
    return round(paper_gain(paper) - GAIN_TOLERANCE, 6)


def claim_context(ctx: Context, spec: ClaimBudget, budget: int | None, below: bool) -> Context:
    """``ctx`` for one claim: the claim's budget and seed minimum (or, ``below``, an indicative reading)."""
    key = ("claim-context", spec.kind, budget, spec.min_seeds, ctx.min_seeds, below)
    if key not in ctx.cache:
        label = "its configured offline.updates" if spec.kind == "offline_updates" and not below else None
        if spec.kind == "offline_updates" and below:
            label = "the latest evaluation"
        ctx.cache[key] = replace(ctx, budget=budget if budget is not None else ctx.budget, below_budget=below,
                                 min_seeds=1 if below else max(spec.min_seeds, ctx.min_seeds),
                                 budget_label=label, cache=ctx.cache)
    return ctx.cache[key]


def short_of_budget(ctx: Context, spec: ClaimBudget) -> str | None:
    """Why the claim's runs cannot carry a verdict at its budget, or None if they may."""
    if spec.kind == "none":
        return None
    runs = claim_runs(ctx.scores, spec, ctx.experiment_map, offline=spec.kind == "offline_updates")
    r = reach(runs)
    names = ", ".join(select.expand_experiments(spec.experiments, ctx.experiment_map))
    if r.runs == 0:
        hint = claim_hint(ctx.scores, spec, ctx.experiment_map)
        return f"no runs in experiment(s) {names}; the claim is about {spec.text()}" + (f"; {hint}" if hint else "")
    if spec.kind == "offline_updates":
        if r.done == 0:
            return f"none of the {r.runs} offline runs has finished its configured offline.updates"
        return None
    if spec.budget is not None and not comparable.reached(r.highest, spec.budget):
        return f"{r.describe()}; the claim is about {spec.text()}"
    return None


def judge_check(ctx: Context, fn: Check) -> tuple[str, str]:
    try:
        return fn(ctx)
    except NotEnoughData as exc:
        return NO_DATA, str(exc)


def budget_words(paper: PaperData, claim: str, words: str) -> str:
    """A ``holds`` / ``fails`` wording of claim_budgets.csv as shown: each ``{name}`` in it is the claim's number
    ``name`` of claim_numbers.csv ("TACO about {gain}x DrQ-v2"), ``{gain_bar}`` online_avg_gain's bar
    (:func:`gain_bar`). KeyError for a name the claim has no number for."""
    numbers = paper.claim_numbers[paper.claim_numbers["claim"] == claim]
    values = {str(n): float(v) for n, v in zip(numbers["name"], numbers["value"])}
    if claim == "online_avg_gain":
        values["gain_bar"] = gain_bar(paper)
    return words.format_map({n: f"{v:g}" for n, v in values.items()})


def indicative_reading(ctx: Context, spec: ClaimBudget, fn: Check) -> tuple[str, str]:
    """A reading at the frames every run of the claim reaches (the lowest last frame, capped at the
    claim's budget), one seed per cell allowed: (label, evidence), or ("", reason) if there is none."""
    runs = claim_runs(ctx.scores, spec, ctx.experiment_map, offline=spec.kind == "offline_updates")
    if spec.kind == "frames" and spec.budget is not None:
        r = reach(runs)
        if r.runs == 0 or not r.lowest > 0:
            return "", "no indicative reading: " + ("no runs" if r.runs == 0
                                                     else "a run has no evaluation past frame 0")
        budget = int(min(r.lowest, spec.budget))
        where = frames_text(budget)
    else:
        budget, where = None, "latest evaluations" if spec.kind == "offline_updates" else "measurements"
    verdict, evidence = judge_check(claim_context(ctx, spec, budget, below=True), fn)
    if verdict == NO_DATA:
        return "", f"no indicative reading at {where}: {evidence}"
    words = budget_words(ctx.paper, spec.id, spec.holds if verdict == SUPPORTED else spec.fails)
    label = f"indicative: {words} ({where}, {seed_counts(runs)})"
    return label, f"indicative reading at {where}, below the claim's budget or seed count: {evidence}"


def read_claim(ctx: Context, spec: ClaimBudget, short: str | None, fn: Check) -> tuple[str, str, str]:
    """(verdict, evidence, indicative label) of claim function ``fn`` under the budget rule: no data when the
    runs fall ``short`` of the claim's budget (with a labelled indicative reading on request), else judged."""
    if short is not None:
        verdict, evidence = NO_DATA, short
    else:
        verdict, evidence = judge_check(claim_context(ctx, spec, spec.budget, below=False), fn)
    evidence = f"at {spec.text()}: {evidence}"
    label = ""
    if verdict == NO_DATA and ctx.indicative:
        label, extra = indicative_reading(ctx, spec, fn)
        evidence = f"{evidence}. {extra}"
    return verdict, evidence, label


