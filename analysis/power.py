"""Statistical power of each claim before the runs: the probability that the claim's own rule, applied as
``repro claims`` applies it, says "supported" if the paper's numbers are the truth (``repro plan --claims``).

* **Cells.** Each simulated claim names its cells (task x method, or task x dataset x method) and where each
  cell's truth comes from in its spec (analysis.claims.SPECS, built from analysis/cells.py, which says how each
  kind of cell is drawn). A baseline the claim reads from the paper itself (DreamerV3 and TD-MPC in Table 1, the
  published DrQ-v2 curves against which ``online_avg_gain_vs_published`` is read) is fixed, not drawn.

* **Rule.** The claim's rule in analysis.claims (the function ``repro claims`` calls on the runs as one draw, with
  the same seed minimum) judges every draw at once: it takes the cells with a leading draws axis, (draws, seeds)
  per cell, and gives the verdict of each draw; a cell with fewer seeds than the claim's minimum is "not enough
  data". Rules whose verdict reads a point estimate run with ``reps`` 0 (the point alone, the CI is only
  evidence); offline_average, whose verdict reads a bootstrap CI, runs rliable's bootstrap in every draw
  (``Simulation.reps`` repetitions, fewer draws; analysis.bootstrap.draw_intervals).

* **Monte-Carlo error.** The power p over S draws has standard error sqrt(p (1 - p) / S); every draw comes
  from one NumPy Generator seeded from (seed, claim, seeds per cell), so a fixed ``seed`` gives the same table.

* **Seeds for 80%.** The smallest seeds per cell (>= the claim's minimum, <= ``max_seeds``) whose simulated
  power is >= 80%: power at the minimum, then doubling, then bisection (the power of these rules grows with
  the seeds, up to the Monte-Carlo error).

* **Conditioned on runs** (:func:`conditioned_power`): the values of the seeds already done stay as they are in
  each cell; only the missing seeds are drawn from the cell's source.

A claim whose rule cannot be simulated from what is known (a learning-curve rule, a figure-only number, a
single run, a timing) is listed with the reason its spec gives (``ClaimSpec.not_simulated``).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from analysis import claims as cl
from analysis.cells import Cells, CellSource, Key
from analysis.claim_budget import ClaimBudget, load_budgets
from analysis.claims import Draws, Judge
from analysis.context import Context
from analysis.load import Results
from analysis.paper import PaperData
from analysis.tables import TableOutput, fmt_num, write_table

if TYPE_CHECKING:
    from analysis.audit import Finding

TARGET = 0.8  # the power "seeds for 80%" asks for
DEFAULT_SIMS = 2000
DEFAULT_MAX_SEEDS = 50
REPORT_SIMS, REPORT_MAX_SEEDS = 500, 20  # the report's section: fewer draws, a shorter search


# ---------------------------------------------------------------- simulated claims
@dataclass
class SimClaim:
    """One claim as the simulation runs it: its cells, its rule ``judge(ctx, draws) -> Judgement`` (every draw's
    verdict at once: analysis.claims.Judge), and the user's values per cell (``observed(ctx)``, from the runs that
    reached the claim's budget)."""

    id: str
    spec: ClaimBudget
    cells: list[CellSource]
    judge: Judge
    observed: Callable[[Context], Cells] | None = None
    tasks: tuple[str, ...] = ()  # the tasks of its runs (what its seeds cost)
    sims: int | None = None  # draws (default: the caller's)
    reps: int = 0  # bootstrap repetitions the rule runs in each draw
    notes: list[str] = field(default_factory=list)
    # simulate()'s results by its arguments: the table asks for the same power more than once (at the claim's
    # minimum, and first in the search for 80%)
    memo: dict[Hashable, Power] = field(default_factory=dict, repr=False, compare=False)


def simulated_claims(ctx: Context, budgets: Mapping[str, ClaimBudget] | None = None,
                     specs: Sequence[cl.ClaimSpec] | None = None) -> list[SimClaim]:
    """Every claim whose spec has a simulation (analysis.claims.SPECS), in claims.csv's order, with its cells'
    sources from the paper (``ctx.paper``) and the published DrQ-v2 curves (``ctx.published``) at its budget.
    ``specs``: the claims as listed for ``ctx.paper`` (analysis.claims.claim_specs, called here when None)."""
    budgets = budgets or load_budgets()
    out = []
    for spec in cl.claim_specs(ctx.paper) if specs is None else specs:
        sim = spec.simulation
        if sim is None:
            continue
        budget = budgets[spec.claim_id]
        notes = sim.notes_text(ctx.paper)
        if sim.reps:
            notes.append(f"its verdict reads a bootstrap CI: rliable's bootstrap runs in every draw ({sim.reps} "
                         f"repetitions instead of {ctx.reps:,}; {sim.sims} draws)")
        out.append(SimClaim(spec.id, budget, sim.sources(ctx, float(budget.budget or 0)), sim.judge, sim.observed,
                            sim.tasks, sim.sims, sim.reps, notes))
    return out


# ---------------------------------------------------------------- simulation
class _MemoPaper(PaperData):
    """The paper's tables with memoised cell lookups: a rule reads the same printed baselines in every draw."""

    def __init__(self, paper: PaperData) -> None:
        super().__init__(paper.root)
        self._online: dict[tuple[str, str], tuple[float, float] | None] = {}
        self._repr: dict[tuple[str, str], tuple[float, float] | None] = {}

    def online_value(self, task: str, method: str) -> tuple[float, float] | None:
        if (task, method) not in self._online:
            self._online[(task, method)] = super().online_value(task, method)
        return self._online[(task, method)]

    def repr_value(self, task: str, method: str) -> tuple[float, float] | None:
        if (task, method) not in self._repr:
            self._repr[(task, method)] = super().repr_value(task, method)
        return self._repr[(task, method)]


def sim_context(ctx: Context, claim: SimClaim, min_seeds: int = 1) -> Context:
    """The context a rule sees in the simulation: the claim's budget and seed minimum, no runs, no CI unless
    the verdict reads one (``claim.reps``)."""
    empty = Results(Path("."), pd.DataFrame(), pd.DataFrame())
    budget = claim.spec.budget if claim.spec.budget is not None else ctx.budget
    return Context(results=empty, paper=_MemoPaper(ctx.paper), budget=budget, reps=claim.reps, seed=ctx.seed,
                   min_seeds=max(claim.spec.min_seeds, min_seeds), cache={})


@dataclass(frozen=True)
class Power:
    """P(supported) and P(refuted) over ``sims`` draws at ``seeds`` per cell, with the Monte-Carlo error."""

    seeds: int
    supported: float
    refuted: float
    sims: int

    @property
    def error(self) -> float:
        """The Monte-Carlo standard error of ``supported``."""
        return math.sqrt(self.supported * (1 - self.supported) / self.sims)

    def text(self) -> str:
        return f"{self.supported:.2f} ± {self.error:.2f}"


def _rng(seed: int, claim_id: str, seeds: int) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32(claim_id.encode()), seeds])


def simulate(ctx: Context, claim: SimClaim, seeds: int, sims: int = DEFAULT_SIMS, seed: int = 0,
             observed: Cells | None = None, min_seeds: int = 1) -> Power:
    """The claim's verdicts over ``sims`` draws with ``seeds`` per cell (the ``observed`` values of a cell kept,
    only its missing seeds drawn); computed once per claim and arguments (``claim.memo``)."""
    key = (id(ctx.paper), ctx.budget, seeds, sims, seed, min_seeds,
           tuple(sorted((k, np.asarray(v, dtype=float).tobytes()) for k, v in (observed or {}).items())))
    if key not in claim.memo:
        claim.memo[key] = _simulate(ctx, claim, seeds, sims, seed, observed, min_seeds)
    return claim.memo[key]


def _simulate(ctx: Context, claim: SimClaim, seeds: int, sims: int, seed: int, observed: Cells | None,
              min_seeds: int) -> Power:
    sims = min(claim.sims, sims) if claim.sims else sims
    rng = _rng(seed, claim.id, seeds)
    sctx = sim_context(ctx, claim, min_seeds)
    arrays: dict[Key, np.ndarray] = {}
    for cell in claim.cells:
        have = np.asarray((observed or {}).get(cell.key, np.empty(0)), dtype=float)
        new = cell.draw(rng, sims, max(0, seeds - len(have)) if cell.kind != "fixed" else 0)
        arrays[cell.key] = np.concatenate([np.broadcast_to(have, (sims, len(have))), new], axis=1) \
            if cell.kind != "fixed" else new
    if not arrays or all(a.shape[0] == sims and (a == a[:1]).all() for a in arrays.values()):
        # every draw is the same data (no seed left to draw: the seeds done, or fixed cells): one draw judges all
        verdicts = np.repeat(draw_verdicts(sctx, claim, {k: a[:1] for k, a in arrays.items()}), sims)
    else:
        verdicts = draw_verdicts(sctx, claim, arrays)
    return Power(seeds, float(np.mean(verdicts == cl.SUPPORTED)), float(np.mean(verdicts == cl.REFUTED)), sims)


def draw_verdicts(sctx: Context, claim: SimClaim, draws: Draws) -> np.ndarray:
    """The claim's verdict in every draw, by its rule (not enough data in all of them where it raises so)."""
    try:
        return claim.judge(sctx, draws).verdicts
    except cl.NotEnoughData:
        return np.full(cl.n_draws(draws), cl.NO_DATA, dtype=object)


def seeds_for(ctx: Context, claim: SimClaim, target: float = TARGET, sims: int = DEFAULT_SIMS, seed: int = 0,
              max_seeds: int = DEFAULT_MAX_SEEDS, observed: Cells | None = None,
              min_seeds: int = 1) -> tuple[int | None, Power]:
    """The fewest seeds per cell (from the claim's minimum up to ``max_seeds``) with simulated power >= ``target``,
    and the power there; (None, the power at ``max_seeds``) if none reaches it."""
    lo = max(claim.spec.min_seeds, min_seeds, max((len(v) for v in (observed or {}).values()), default=0))

    def power(n: int) -> Power:
        return simulate(ctx, claim, n, sims, seed, observed, min_seeds)

    first = power(lo)
    if first.supported >= target:
        return lo, first
    fail, n = lo, lo
    while True:
        n = min(2 * n, max_seeds)
        p = power(n)
        if p.supported >= target:
            break
        if n >= max_seeds:
            return None, p
        fail = n
    best = (n, p)
    lo_n, hi_n = fail, n
    while hi_n - lo_n > 1:
        mid = (lo_n + hi_n) // 2
        pm = power(mid)
        if pm.supported >= target:
            hi_n, best = mid, (mid, pm)
        else:
            lo_n = mid
    return best


# ---------------------------------------------------------------- tables
@dataclass
class PowerRow:
    """One claim of the power table: at the claim's seed minimum and at the paper's seed count, the seeds for
    80%, and (with runs) the power given the seeds done."""

    id: str
    simulated: bool
    rule: str
    min_seeds: int
    paper_seeds: int
    at_min: Power | None = None
    at_paper: Power | None = None
    seeds_80: int | None = None
    at_80: Power | None = None
    reason: str = ""
    notes: list[str] = field(default_factory=list)
    done_seeds: int = 0  # fewest seeds done in a cell of the claim (with runs)
    now: Power | None = None  # P(supported) at the claim's minimum given the seeds done
    more_80: int | None = None  # more seeds per cell (beyond the most done in a cell) for 80% given those done
    verdict: str = ""  # `repro claims` verdict and evidence now (with runs)
    evidence: str = ""
    cells: list[CellSource] = field(default_factory=list)
    tasks: tuple[str, ...] = ()  # the tasks of the claim's runs
    experiments: tuple[str, ...] = ()  # the experiments (sweeps) the claim reads
    audit: str = ""  # the audit finding that bounds the claim's power (:func:`audit_limit`), "" when none does


def power_rows(ctx: Context, sims: int = DEFAULT_SIMS, max_seeds: int = DEFAULT_MAX_SEEDS,
               verdicts: Sequence[cl.Verdict] | None = None, conditioned: bool = False,
               bootstrap_claims: bool = True, findings: Sequence[Finding] | None = None,
               specs: Sequence[cl.ClaimSpec] | None = None) -> list[PowerRow]:
    """One row per claim of analysis.claims.claim_specs (claims.csv's order, the published-curves reading of
    online_avg_gain after it). ``conditioned``: also the power given the user's runs in ``ctx`` (and their
    ``verdicts``); ``bootstrap_claims`` False: leave out the claims whose rule runs a bootstrap in every draw (the
    report). ``findings``: the audit of ``ctx.paper`` (analysis/audit.py; None: run here, once, if a claim's power
    needs it); ``specs``: the claims as ``claim_specs(ctx.paper)`` lists them (None: listed here). The report passes
    both, built once (analysis/report_model.py)."""
    budgets = load_budgets()
    specs = cl.claim_specs(ctx.paper) if specs is None else specs
    sim = {c.id: c for c in simulated_claims(ctx, budgets, specs)}
    by_verdict = {v.id: v for v in verdicts or []}
    rows = []
    for claim in specs:
        cid, rule, spec = claim.id, claim.rule_text(ctx.paper), budgets.get(claim.claim_id)
        if spec is None:
            rows.append(PowerRow(cid, False, rule, 0, 0, reason="no budget in claim_budgets.csv"))
            continue
        seeds = max(spec.min_seeds, ctx.min_seeds)
        row = PowerRow(cid, cid in sim, rule, seeds, spec.paper_seeds, experiments=spec.experiments)
        if cid in by_verdict:
            row.verdict, row.evidence = by_verdict[cid].shown, by_verdict[cid].evidence
        if cid not in sim:
            row.reason = claim.not_simulated
            rows.append(row)
            continue
        c = sim[cid]
        if c.reps and not bootstrap_claims:
            row.simulated, row.reason = False, ("its rule runs a bootstrap in every draw: simulated by `repro plan "
                                                "--claims`, not here")
            rows.append(row)
            continue
        row.cells, row.notes, row.tasks = c.cells, c.notes, c.tasks
        row.at_min = simulate(ctx, c, seeds, sims, ctx.seed, min_seeds=ctx.min_seeds)
        row.at_paper = simulate(ctx, c, max(spec.paper_seeds, seeds), sims, ctx.seed, min_seeds=ctx.min_seeds)
        row.seeds_80, row.at_80 = seeds_for(ctx, c, TARGET, sims, ctx.seed, max_seeds, min_seeds=ctx.min_seeds)
        if conditioned and c.observed is not None:
            condition_row(ctx, c, row, sims, max_seeds)
        if claim.audit and _short_of_target(row):
            if findings is None:
                from analysis.audit import run_audit

                findings = run_audit(ctx.paper)
            row.audit = audit_limit(findings, claim.audit)
        rows.append(row)
    return rows


def _short_of_target(row: PowerRow) -> bool:
    """Whether the claim's power stays under :data:`TARGET` at the paper's seeds or given the seeds done."""
    return any(p is not None and p.supported < TARGET for p in (row.at_paper, row.now)) or (
        row.simulated and row.seeds_80 is None)


def audit_limit(findings: Sequence[Finding], checks: Sequence[str]) -> str:
    """The audit's ``findings`` (analysis/audit.py) of ``checks`` that do not match, as the power table names them:
    the cause of a power that no number of seeds lifts, where the paper's own numbers disagree with the data the
    claim is read against ("" when every one matches)."""
    bad = [f for f in findings if f.check in checks and not f.match]
    return "; ".join(f"limited by the audit's finding {f.check} ({f.where}): {f.recomputed} where the paper gives "
                     f"{f.printed} (audit.md)" for f in bad)


def condition_row(ctx: Context, claim: SimClaim, row: PowerRow, sims: int, max_seeds: int) -> None:
    """Fill the conditioned columns of ``row`` from the user's runs at the claim's budget: the cells its check read
    there (the claim's context and its cells are kept in ``ctx.cache``: analysis.claims.claim_cells), read now only
    where `repro claims` did not read them."""
    cctx = cl.claim_context(ctx, claim.spec, claim.spec.budget, below=False)
    observed = {k: v for k, v in cl.claim_cells(cctx, claim.observed).items() if k in {c.key for c in claim.cells}} \
        if claim.observed is not None else {}
    drawn = [c.key for c in claim.cells if c.kind != "fixed"]
    row.done_seeds = min((len(observed.get(k, ())) for k in drawn), default=0)
    most = max((len(v) for v in observed.values()), default=0)
    row.now = simulate(ctx, claim, max(row.min_seeds, most), sims, ctx.seed, observed, ctx.min_seeds)
    n80, _ = seeds_for(ctx, claim, TARGET, sims, ctx.seed, max_seeds, observed, ctx.min_seeds)
    row.more_80 = None if n80 is None else n80 - row.done_seeds


def _seeds_text(row: PowerRow, max_seeds: int) -> str:
    if not row.simulated:
        return ""
    return str(row.seeds_80) if row.seeds_80 is not None else f"> {max_seeds}"


def power_frames(rows: Sequence[PowerRow], max_seeds: int = DEFAULT_MAX_SEEDS,
                 cost: Callable[[str, int], str] | None = None,
                 conditioned: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of the power table; ``cost(claim, seeds)`` says what those seeds cost."""
    raw = pd.DataFrame([{
        "id": r.id, "simulated": r.simulated, "min_seeds": r.min_seeds, "paper_seeds": r.paper_seeds,
        "power_at_min": r.at_min.supported if r.at_min else math.nan,
        "mc_error_at_min": r.at_min.error if r.at_min else math.nan,
        "power_at_paper_seeds": r.at_paper.supported if r.at_paper else math.nan,
        "mc_error_at_paper_seeds": r.at_paper.error if r.at_paper else math.nan,
        "refuted_at_paper_seeds": r.at_paper.refuted if r.at_paper else math.nan,
        "sims": r.at_min.sims if r.at_min else 0, "seeds_for_80": r.seeds_80,
        "power_at_seeds_for_80": r.at_80.supported if r.at_80 else math.nan,
        "cost_of_seeds_for_80": cost(r.id, r.seeds_80) if cost and r.seeds_80 else "",
        "verdict_now": r.verdict, "evidence_now": r.evidence, "seeds_done": r.done_seeds,
        "power_given_done": r.now.supported if r.now else math.nan, "more_seeds_for_80": r.more_80,
        "not_simulated_because": r.reason, "audit": r.audit, "notes": "; ".join(r.notes), "rule": r.rule,
    } for r in rows])
    display = pd.DataFrame({
        "Claim": [r.id for r in rows],
        "Seeds (min / paper)": [f"{r.min_seeds} / {r.paper_seeds}" if r.min_seeds else "" for r in rows],
        "P(supported) at min": [r.at_min.text() if r.at_min else "not simulated" for r in rows],
        "at paper's seeds": [r.at_paper.text() if r.at_paper else "" for r in rows],
        "Seeds for 80%": [_seeds_text(r, max_seeds) for r in rows],
        "Cost of those seeds": [cost(r.id, r.seeds_80) if cost and r.seeds_80 else "" for r in rows],
    })
    if conditioned:
        display["Now"] = [r.verdict for r in rows]
        display["Seeds done"] = [str(r.done_seeds) if r.simulated else "" for r in rows]
        display["P(supported) given done"] = [fmt_num(r.now.supported, 2) if r.now else "" for r in rows]
        display["More seeds for 80%"] = [("" if not r.now else str(r.more_80) if r.more_80 is not None
                                          else f"> {max_seeds - r.done_seeds}") for r in rows]
    display["Why not simulated / notes"] = [r.reason or "; ".join(([r.audit] if r.audit else []) + r.notes)
                                            for r in rows]
    return raw, display


def cells_frame(rows: Sequence[PowerRow]) -> pd.DataFrame:
    """One row per simulated cell: claim, cell, the truth assumed, its source and its distribution."""
    return pd.DataFrame([{"Claim": r.id, "Cell": "/".join(str(p) for p in c.key),
                          "Mean": fmt_num(c.mean) if c.kind != "fixed" else fmt_num(np.mean(c.values)),
                          "Std": fmt_num(c.std), "Source": c.source, "Distribution": c.describe()}
                         for r in rows for c in r.cells], columns=["Claim", "Cell", "Mean", "Std", "Source",
                                                                   "Distribution"])


def power_notes(sims: int, seed: int, max_seeds: int) -> list[str]:
    """The assumptions stated under the power table."""
    return [
        "P(supported): the probability that the claim's rule, applied as `repro claims` applies it (same statistic, "
        "same seed minimum, analysis/claims/), says 'supported' if the paper's numbers are the truth; ± is the "
        f"Monte-Carlo standard error over {sims:,} draws (fewer where stated), random state {seed}.",
        "Cells: DrQ-v2 on a DMC task draws the DrQ-v2 authors' published per-seed values at the claim's budget "
        "(interpolated between evaluations), shifted to Table 1's mean; every other cell is normal with the "
        "paper's mean and std, truncated at the return range; each cell's source: plan_power_cells.",
        "These rules compare means with no significance threshold: two equal cells give 'supported' about half "
        "the time, so a high P(supported) says the paper's gap is large against the seed noise, not that a "
        "test controls false positives.",
        f"Seeds for 80%: the fewest seeds per cell (from the claim's minimum, at most {max_seeds}) with simulated "
        "P(supported) >= 0.8, found by doubling then bisection.",
    ]


def write_power(out_dir: Path, rows: Sequence[PowerRow], sims: int, seed: int,
                max_seeds: int = DEFAULT_MAX_SEEDS, cost: Callable[[str, int], str] | None = None,
                conditioned: bool = False, extra_notes: Sequence[str] = ()) -> tuple[TableOutput, TableOutput]:
    """Write ``plan_power.csv/.md/.tex`` and ``plan_power_cells.csv/.md/.tex``."""
    raw, display = power_frames(rows, max_seeds, cost, conditioned)
    n_sim = sum(r.simulated for r in rows)
    caption = (f"Statistical power of each claim if the paper's numbers are the truth ({n_sim} of {len(rows)} "
               "claims simulated through their own rules)"
               + ("; conditioned on the runs done" if conditioned else "") + ".")
    notes = power_notes(sims, seed, max_seeds) + list(extra_notes)
    if conditioned:
        notes.append("Given done: the values of the seeds already run (that reached the claim's budget) are kept in "
                     "each cell, only the missing seeds are drawn; More seeds for 80%: per cell, beyond the fewest "
                     "done in a cell.")
    table = write_table(out_dir, "plan_power", raw, caption, display, notes)
    cells = cells_frame(rows)
    cells_table = write_table(out_dir, "plan_power_cells", cells,
                              "The truth assumed in every simulated cell, with its source and distribution.")
    return table, cells_table


def next_runs_paragraph(rows: Sequence[PowerRow], max_seeds: int = DEFAULT_MAX_SEEDS) -> str:
    """The report's "what to run next": per simulated claim still short of a verdict or below 80%, the seeds."""
    lines = []
    for r in rows:
        if not r.simulated or r.now is None:
            continue
        if r.more_80 is None:
            lines.append(f"- `{r.id}` ({r.verdict or 'no verdict'}): P(supported) {r.now.supported:.2f} given the "
                         f"{r.done_seeds} seed(s) done; even {max_seeds} seeds per cell would not reach 80% if the "
                         "paper's numbers are the truth" + (f": {r.audit}." if r.audit else "."))
        elif r.more_80 > 0:
            lines.append(f"- `{r.id}` ({r.verdict or 'no verdict'}): P(supported) {r.now.supported:.2f} given the "
                         f"{r.done_seeds} seed(s) done; {r.more_80} more seed(s) per cell reach 80%.")
    if not any(r.now is not None for r in rows):
        return ("What to run next: no runs yet. If the paper's numbers are the truth, column 'Seeds for 80%' gives "
                "the seeds per cell that each simulated claim needs.")
    if not lines:
        return "Every simulated claim already reaches 80% power with the seeds done."
    return "What to run next (if the paper's numbers are the truth):\n\n" + "\n".join(lines)
