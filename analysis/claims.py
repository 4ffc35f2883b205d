"""A verdict for every claim of ``claims.csv`` from the user's runs: supported / refuted / not enough data.

Rules (also in docs/analysis.md): each claim is judged at its own budget with its own minimum number of
seeds (``analysis/claim_budgets.csv``: 1M frames for most, 1.5M, 2M, 30M, or an offline run's own
configured ``offline.updates``), never at the budget the runs happen to reach. Verdicts compare point
estimates (means over the seeds that reached the claim's budget) with the tolerances written in each
rule; 95% CIs are reported beside them. A cell with fewer seeds than the claim's minimum counts as
missing. A claim about every task ("on each of the nine tasks") is refuted by one counterexample among
the cells that exist, even if others are missing. When the runs fall short, the verdict is "not enough
data" with the reason; on request (``Context.indicative``) an indicative reading at the frames the runs
reach is added, labelled as such and never counted as supported or refuted.

Each claim is defined once, in :data:`SPECS` (:class:`ClaimSpec`: its check and rule, its cells from the runs and
from the paper for the power simulation, or why it is not simulated); `repro claims`, `repro plan --claims`
(analysis/power.py) and the report list the claims through :func:`claim_specs`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np
import pandas as pd

from analysis import bootstrap as bs
from analysis import comparable, select
from analysis.calibration import SOURCE_TEXT, published_values
from analysis.cells import (
    Cells,
    CellSource,
    Key,
    drqv2_cell,
    means_table,
    observed_cells,
    published_fixed_cells,
    solve_upper_bound,
    solved_cells,
    stacked,
    table1_cells,
    table2_cells,
    table3_cells,
)
from analysis.claim_budget import ClaimBudget, claim_hint, claim_runs, frames_text, load_budgets, reach, seed_counts
from analysis.context import Context
from analysis.offline_tables import offline_runs
from analysis.paper import DMC9, METAWORLD6, OFFLINE_TASKS, PaperData
from analysis.robustness import BROKEN_FRACTION, cell_spread, seed_spread, solved_counts
from analysis.speed import speed_measurements
from analysis.stats import grand_mean_ci, ratio_of_means, ratio_to_task_means, score_matrix
from analysis.tables import write_table
from analysis.tsne import CLUSTER_THRESHOLD, tsne_for_context
from repro.config.schema import DatasetKind

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
    """Raised by a check when the cells it needs are missing or have too few seeds."""


Check = Callable[[Context], tuple[str, str]]  # a claim's check on the runs: (verdict, evidence)
# A text as written, or one built from the paper data (a rule or note that quotes a number the paper prints)
PaperText = str | Callable[[PaperData], str]


def paper_text(text: PaperText, paper: PaperData) -> str:
    """``text`` as shown for ``paper``: built from its numbers where it quotes them."""
    return text(paper) if callable(text) else text


@dataclass(frozen=True)
class Simulation:
    """How the power simulation (analysis/power.py) runs a claim: ``sources(ctx, budget)`` the claim's cells with
    where the paper gives each (analysis/cells.py), ``judge(ctx, cells)`` building the check's input from one draw
    and calling the claim's rule (the function its check calls), ``observed(ctx)`` the same cells from the user's
    runs (None: not conditioned on runs), ``tasks`` those of its runs (what its seeds cost), ``sims`` the draws if
    fewer than the caller's, ``reps`` the bootstrap repetitions the rule runs in every draw (0: none)."""

    sources: Callable[[Context, float], list[CellSource]]
    judge: Callable[[Context, Cells], tuple[str, str]]
    observed: Callable[[Context], Cells] | None
    tasks: tuple[str, ...]
    sims: int | None = None
    reps: int = 0
    notes: tuple[PaperText, ...] = ()
    batch: BatchJudge | None = None  # ``judge`` on every draw at once (:data:`BatchJudge`); None: draw by draw

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


# ---------------------------------------------------------------- helpers
def means(df: pd.DataFrame, keys: Sequence[str], value: str = "score") -> dict[tuple, tuple[int, float]]:
    """(n, mean) per key over the runs that reached the budget."""
    out: dict[tuple, tuple[int, float]] = {}
    if df.empty:
        return out
    ok = df[df["reached"].astype(bool) & df[value].notna()]
    for key, rows in ok.groupby(list(keys)):
        out[key if isinstance(key, tuple) else (key,)] = (len(rows), float(rows[value].mean()))
    return out


def get(ctx: Context, table: dict[tuple, tuple[int, float]], *key) -> float | None:
    """The mean of a cell with at least ``ctx.min_seeds`` seeds, else None."""
    n, mean = table.get(tuple(key), (0, math.nan))
    return mean if n >= ctx.min_seeds else None


def present(ctx: Context, table: dict[tuple, tuple[int, float]], *key) -> float:
    """``get`` of a cell already known to have enough seeds (checked by ``require`` or by a ``get``)."""
    value = get(ctx, table, *key)
    assert value is not None, key
    return value


def require(ctx: Context, table: dict, keys: Sequence[tuple]) -> None:
    missing = [k for k in keys if get(ctx, table, *k) is None]
    if missing:
        shown = ", ".join("/".join(str(p) for p in k) for k in missing[:6])
        more = f" (+{len(missing) - 6} more)" if len(missing) > 6 else ""
        raise NotEnoughData(f"need >= {ctx.min_seeds} seeds that reached {ctx.budget_text()} for: {shown}{more}")


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


def universal(ctx: Context, table: dict, pairs: Sequence[tuple[tuple, tuple, str]]) -> tuple[str, str]:
    """Check 'A > B' for every (A key, B key, name): refuted by any counterexample present, supported if all hold."""
    fails, lines, missing = [], [], []
    for a, b, name in pairs:
        va, vb = get(ctx, table, *a), get(ctx, table, *b)
        if va is None or vb is None:
            missing.append(name)
            continue
        lines.append(f"{name}: {vs_text(va, vb, 1)}")
        if not va > vb:
            fails.append(name)
    evidence = "; ".join(lines)
    if fails:
        return REFUTED, f"fails on {', '.join(fails)}. {evidence}"
    if missing:
        raise NotEnoughData(f"need >= {ctx.min_seeds} seeds that reached {ctx.budget_text()} for: {', '.join(missing)}"
                            + (f". So far: {evidence}" if evidence else ""))
    return SUPPORTED, evidence


def labelled(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=["method"], errors="ignore").rename(columns={"label": "method"}) if "label" in df else df


def online_rows(ctx: Context) -> pd.DataFrame:
    """The runs of the main online experiment, with the label as the method (the rows of the Table 1 claims)."""
    return labelled(select.online_main(ctx.scores, ctx.experiment_map))


# The rules below take a claim's cells (a ``means`` table, score matrices or per-cell summaries) instead of the
# runs, so that the power simulation (analysis.power) applies them, unchanged, to simulated cells.
GAIN_TOLERANCE = 0.1  # online_avg_gain: how far short of the paper's "about 1.4x" the ratio may fall
SPEED_TOLERANCE = 0.25  # speed: the FPS ratio within this fraction of the paper's "about 3.6x slower"
MODEL_BASED_WINS = 6  # online_beats_model_based: tasks of 9 on which TACO must beat both model-based baselines
LESS_SPREAD_TASKS = 7  # seed_robustness: tasks of 9 on which TACO's std over seeds must be below DrQ-v2's
SOLVED_FRACTION = 1 / 3  # manipulator: the fraction of TACO's seeds that must solve ("a third"; the paper: 3 of 6)
REPR_TASKS = ("quadruped_run", "walker_run", "hopper_hop", "reacher_hard", "acrobot_swingup")
OFFLINE_AVERAGED = ("TD3+BC+TACO", "TD3+BC", "CQL+TACO", "CQL")  # offline_average's methods: the +-TACO pairs
MODEL_BASED = ("DreamerV3", "TD-MPC")


def paper_gain(paper: PaperData) -> float:
    """online_avg_gain's "about 1.4x" as the paper's prose gives it (repro_data/paper/claim_numbers.csv)."""
    return paper.claim_number("online_avg_gain", "gain")


def gain_bar(paper: PaperData) -> float:
    """The ratio online_avg_gain needs: the paper's gain less :data:`GAIN_TOLERANCE` (1.4 - 0.1 = 1.3), rounded to
    6 decimals so that the subtraction's last bit (1.4 - 0.1 is 1.2999999999999998 in floats) moves no verdict."""
    return round(paper_gain(paper) - GAIN_TOLERANCE, 6)


def _gain_rule_text(paper: PaperData) -> str:
    return (f"mean over the 9 tasks of TACO / DrQ-v2 >= {gain_bar(paper):g} (about {paper_gain(paper):g}x, "
            f"tolerance {GAIN_TOLERANCE:g}); CI by rliable bootstrap")


def offline_printed(ctx: Context) -> dict[str, float]:
    """Table 3's printed average of each method of ``offline_average``, read from the packaged paper data
    (repro_data/paper/offline_average.csv), never repeated here."""
    avg = ctx.paper.offline_average
    printed = dict(zip(avg["method"], avg["average_normalized"].astype(float)))
    return {m: printed[m] for m in OFFLINE_AVERAGED}


# ---------------------------------------------------------------- checks
def _online_avg_gain(ctx: Context) -> tuple[str, str]:
    df = online_rows(ctx)
    table = means(df, ["task", "method"])
    require(ctx, table, [(t, m) for t in DMC9 for m in ("TACO", "DrQ-v2")])
    ok = df[df["reached"].astype(bool)]
    x, _ = score_matrix(ok[ok["method"] == "TACO"], DMC9)
    y, _ = score_matrix(ok[ok["method"] == "DrQ-v2"], DMC9)
    assert x is not None and y is not None  # require() saw runs on every task
    return avg_gain_rule(ctx, x, y)


def avg_gain_rule(ctx: Context, x: np.ndarray, y: np.ndarray) -> tuple[str, str]:
    """online_avg_gain on TACO's and DrQ-v2's (runs x 9 tasks) score matrices: the verdict reads the ratio of
    means, the CI is evidence (``ctx.reps`` 0: no CI)."""
    r, lo, hi = ratio_of_means(x, y, ctx.reps, ctx.seed)
    verdict = SUPPORTED if r >= gain_bar(ctx.paper) else REFUTED
    shown = apart([r, gain_bar(ctx.paper)], 3)[0]
    return verdict, (f"TACO/DrQ-v2 = {shown} (95% CI [{lo:.3f}, {hi:.3f}]); paper: {paper_gain(ctx.paper):g}x "
                     f"(Table 1 gives {ctx.paper.online_gain:.3f})")


PUBLISHED_GAIN_ID = "online_avg_gain_vs_published"  # the reading of online_avg_gain against the published curves


def _published_gain_rule_text(paper: PaperData) -> str:
    return ("mean over the 9 tasks of TACO (your runs) / DrQ-v2 (the DrQ-v2 authors' published curves, at the same "
            f"frame budget) >= {gain_bar(paper):g}; CI by rliable stratified bootstrap of both, each published task "
            "over its own seeds")


def _online_avg_gain_published(ctx: Context) -> tuple[str, str]:
    """online_avg_gain with the DrQ-v2 authors' published curves as the baseline (no DrQ-v2 runs needed)."""
    df = online_rows(ctx)
    table = means(df, ["task", "method"])
    require(ctx, table, [(t, "TACO") for t in DMC9])
    ok = df[df["reached"].astype(bool)]
    x, _ = score_matrix(ok[ok["method"] == "TACO"], DMC9)
    assert x is not None  # require() saw TACO runs on every task
    frame = float(ctx.budget)
    ys = [published_values(ctx.published, t, frame) for t in DMC9]
    if any(len(y) < ctx.min_seeds for y in ys):
        raise NotEnoughData(f"the published DrQ-v2 curves do not cover {ctx.budget_text()} on every task")
    return published_gain_rule(ctx, x, ys)


def published_gain_rule(ctx: Context, x: np.ndarray, ys: Sequence[np.ndarray]) -> tuple[str, str]:
    """online_avg_gain_vs_published on TACO's (runs x 9 tasks) matrix and the published DrQ-v2 values per task
    at the budget; the verdict reads the ratio, the CI is evidence (``ctx.reps`` 0: no CI)."""
    frame = float(ctx.budget)
    r, lo, hi = ratio_to_task_means(x, ys, ctx.reps, ctx.seed)
    verdict = SUPPORTED if r >= gain_bar(ctx.paper) else REFUTED
    shown = apart([r, gain_bar(ctx.paper)], 3)[0]
    return verdict, (f"TACO/DrQ-v2 (published curves at {frames_text(frame)}) = {shown} (95% CI [{lo:.3f}, {hi:.3f}]); "
                     f"published DrQ-v2 9-task mean {np.mean([np.mean(y) for y in ys]):.1f}; paper: "
                     f"{paper_gain(ctx.paper):g}x (Table 1 gives {ctx.paper.online_gain:.3f} with its own DrQ-v2)")


def _beats_drqv2(ctx: Context) -> tuple[str, str]:
    return beats_drqv2_rule(ctx, means(online_rows(ctx), ["task", "method"]))


def beats_drqv2_pairs() -> list[tuple[tuple, tuple, str]]:
    """online_beats_drqv2_all's comparisons: (TACO cell, DrQ-v2 cell, name) per task."""
    return [((t, "TACO"), (t, "DrQ-v2"), t) for t in DMC9]


def beats_drqv2_rule(ctx: Context, table: dict[tuple, tuple[int, float]]) -> tuple[str, str]:
    """online_beats_drqv2_all on a (task, method) ``means`` table."""
    return universal(ctx, table, beats_drqv2_pairs())


def _beats_model_based(ctx: Context) -> tuple[str, str]:
    return beats_model_based_rule(ctx, means(online_rows(ctx), ["task", "method"]))


def beats_model_based_rule(ctx: Context, table: dict[tuple, tuple[int, float]]) -> tuple[str, str]:
    """online_beats_model_based on a (task, method) ``means`` table (a baseline it lacks: Table 1's value)."""
    require(ctx, table, [(t, "TACO") for t in DMC9])
    wins, used_paper, lines = 0, False, []
    for t in DMC9:
        base = []
        for m in MODEL_BASED:
            v = get(ctx, table, t, m)
            if v is None:
                printed = ctx.paper.online_value(t, m)
                assert printed is not None  # Table 1 has both baselines on every DMC task
                v, used_paper = printed[0], True
            base.append(v)
        taco = present(ctx, table, t, "TACO")
        wins += taco > max(base)
        lines.append(f"{t} {vs_text(taco, max(base), 0)}")
    src = " (DreamerV3/TD-MPC values from the paper, not rerun)" if used_paper else ""
    verdict = SUPPORTED if wins >= MODEL_BASED_WINS else REFUTED
    return verdict, f"TACO beats both on {wins}/9{src}: " + "; ".join(lines)


def _mean_curves(ctx: Context, curves: pd.DataFrame, task: str) -> dict[str, pd.Series]:
    out = {}
    rows = curves[curves["task"] == task] if not curves.empty else curves
    for method, r in rows.groupby("method") if not rows.empty else []:
        piv = r.pivot_table(index="frame", columns="seed", values="value")
        if piv.shape[1] >= ctx.min_seeds:
            out[method] = piv.dropna().mean(axis=1)
    return out


# reacher_speed's bars are this project's reading of "about 0.75M steps while DrQ-v2 needs about 1.5M": TACO within
# this fraction of the budget, DrQ-v2 needing at least this factor more frames (the paper's 2x less a margin).
REACHER_TACO_WITHIN = 2 / 3
REACHER_DRQ_FACTOR = 1.5


def reacher_printed(paper: PaperData) -> str:
    """What reacher_speed's evidence quotes: the prose's steps to the best performance, TACO's and DrQ-v2's
    (repro_data/paper/claim_numbers.csv)."""
    taco = paper.claim_number("reacher_speed", "taco_steps_millions")
    drq = paper.claim_number("reacher_speed", "drqv2_steps_millions")
    return f"(paper: {taco:g}M vs {drq:g}M)"


def _reacher_rule_text(paper: PaperData) -> str:
    budget = load_budgets()["reacher_speed"].budget or 0
    within = Fraction(REACHER_TACO_WITHIN).limit_denominator(10)
    return (f"on reacher_hard, with curves cut at the budget ({budget / 1e6:g}M) and target = 95% of TACO's best "
            f"mean-curve value: TACO reaches it within {within} of the budget "
            f"({REACHER_TACO_WITHIN * budget / 1e6:.1f}M frames) and DrQ-v2 needs >= {REACHER_DRQ_FACTOR:g}x as many "
            "frames (or never does)")


def _reacher_speed(ctx: Context) -> tuple[str, str]:
    curves = labelled(select.online_main(ctx.curves, ctx.experiment_map))
    mc = _mean_curves(ctx, curves, "reacher_hard")
    if "TACO" not in mc or "DrQ-v2" not in mc or min(mc["TACO"].index.max(), mc["DrQ-v2"].index.max()) < ctx.budget:
        raise NotEnoughData(f"need TACO and DrQ-v2 learning curves on reacher_hard up to >= {ctx.budget_text()}")
    mc = {m: c[c.index <= ctx.budget] for m, c in mc.items()}
    target = 0.95 * mc["TACO"].max()
    t_taco = float(mc["TACO"][mc["TACO"] >= target].index.min())
    hit = mc["DrQ-v2"][mc["DrQ-v2"] >= target]
    t_drq = float(hit.index.min()) if len(hit) else None
    # a tie is not sooner (TACO at its target from the first evaluation, DrQ-v2 too: 0 >= 1.5 x 0 is no lead)
    ok = t_taco <= ctx.budget * REACHER_TACO_WITHIN and (
        t_drq is None or (t_drq > t_taco and t_drq >= REACHER_DRQ_FACTOR * t_taco))
    last = float(mc["DrQ-v2"].index.max())
    taco_s, drq_s, last_s = frames_apart([t_taco, t_drq if t_drq is not None else last, last])
    drq_text = drq_s if t_drq is not None else f"not within {last_s}"
    tie = " (a tie: not sooner)" if t_drq == t_taco else ""
    return (SUPPORTED if ok else REFUTED), (f"target {target:.0f}: TACO at {taco_s}, DrQ-v2 {drq_text}{tie} "
                                            + reacher_printed(ctx.paper))


def frames_apart(frames: Sequence[float]) -> list[str]:
    """Frame counts as the claims quote them: '0.75M' from 10K frames on (two decimals, more where two that differ
    would print the same), '400 frames' below (an indicative reading of short runs: not '0.00M')."""
    if all(f >= 10_000 for f in frames):
        return [f"{m}M" for m in apart([f / 1e6 for f in frames], 2)]
    return [f"{int(f):,} frames" if f == int(f) else f"{f:,.1f} frames" for f in frames]


def _longer(ctx: Context) -> tuple[str, str]:
    curves = labelled(select.online_main(ctx.curves, ctx.experiment_map))
    lines, fails, missing = [], [], []
    for t in ("quadruped_run", "hopper_hop", "walker_run", "cheetah_run"):
        mc = _mean_curves(ctx, curves, t)
        if "TACO" not in mc or "DrQ-v2" not in mc:
            missing.append(t)
            continue
        common = mc["TACO"].index.intersection(mc["DrQ-v2"].index)
        if len(common) == 0 or common.max() < ctx.budget:
            missing.append(t)
            continue
        f = common.max()
        lines.append(f"{t} at {f / 1e6:.1f}M: {vs_text(mc['TACO'][f], mc['DrQ-v2'][f], 0)}")
        if not mc["TACO"][f] > mc["DrQ-v2"][f]:
            fails.append(t)
    if fails:
        return REFUTED, f"fails on {', '.join(fails)}: " + "; ".join(lines)
    if missing:
        raise NotEnoughData(f"need curves to >= {ctx.budget_text()} on {', '.join(missing)}")
    return SUPPORTED, "; ".join(lines)


def _metaworld(ctx: Context) -> tuple[str, str]:
    table = means(labelled(select.metaworld(ctx.scores, ctx.experiment_map)), ["task", "method"])
    bases = ["DrQ-v2"] + (["A-LIX"] if any(k[1] == "A-LIX" for k in table) else [])
    verdict, ev = universal(ctx, table, [((t, "TACO"), (t, b), f"{t} vs {b}") for t in METAWORLD6 for b in bases])
    return verdict, ev + ("" if "A-LIX" in bases else " (A-LIX not run: checked against DrQ-v2 only)")


def action_repr_printed(paper: PaperData) -> tuple[str, str]:
    """What action_repr_gain's and no_action_repr_vs_drqv2's evidence quote: the prose's percentages
    (repro_data/paper/claim_numbers.csv)."""
    number = paper.claim_number
    return (f"(paper: +{number('action_repr_gain', 'gain_low_percent'):g}% quadruped_run ... "
            f"+{number('action_repr_gain', 'gain_high_percent'):g}% hopper_hop)",
            f"(paper: +{number('no_action_repr_vs_drqv2', 'quadruped_run_percent'):g}% quadruped_run, "
            f"+{number('no_action_repr_vs_drqv2', 'reacher_hard_percent'):g}% reacher_hard)")


def _action_repr_gain(ctx: Context) -> tuple[str, str]:
    df = select.action_repr(ctx.scores, ctx.experiment_map)
    table = means(df, ["task", "label"])
    tasks = sorted({k[0] for k in table if k[1] == "TACO w/o action repr"}
                   | {"quadruped_run", "hopper_hop", "reacher_hard"})
    verdict, ev = universal(ctx, table, [((t, "TACO"), (t, "TACO w/o action repr"), t) for t in tasks])
    gains = [f"{t} {pct(present(ctx, table, t, 'TACO'), present(ctx, table, t, 'TACO w/o action repr'))}" for t in tasks
             if get(ctx, table, t, "TACO") and get(ctx, table, t, "TACO w/o action repr")]
    return verdict, f"gains {', '.join(gains)} {action_repr_printed(ctx.paper)[0]}. {ev}"


# no_action_repr_vs_drqv2's "comparable elsewhere": this project's reading, within this fraction of DrQ-v2's mean.
COMPARABLE_WITHIN = 0.2


def _no_repr_vs_drqv2(ctx: Context) -> tuple[str, str]:
    df = select.action_repr(ctx.scores, ctx.experiment_map)
    table = means(df, ["task", "label"])
    require(ctx, table, [(t, lab) for t in ("quadruped_run", "reacher_hard")
                         for lab in ("TACO w/o action repr", "DrQ-v2")])
    lines, ok = [], True
    for t in sorted({k[0] for k in table}):
        a, b = get(ctx, table, t, "TACO w/o action repr"), get(ctx, table, t, "DrQ-v2")
        if a is None or b is None:
            continue
        lines.append(f"{t} {pct(a, b)}")
        ok &= (a > b) if t in ("quadruped_run", "reacher_hard") else abs(a / b - 1) <= COMPARABLE_WITHIN
    return (SUPPORTED if ok else REFUTED), ("w/o action repr vs DrQ-v2: " + ", ".join(lines) + " "
                                            + action_repr_printed(ctx.paper)[1])


def _tsne(ctx: Context) -> tuple[str, str]:
    if not ctx.results.runs.empty and "tsne" not in ctx.cache:
        from analysis.tsne import find_tsne_run

        if find_tsne_run(ctx.results.runs) is None:
            raise NotEnoughData("no TACO run with distracting action dims and a checkpoint (experiment 'tsne')")
    elif ctx.results.runs.empty:
        raise NotEnoughData("no runs")
    res, info = tsne_for_context(ctx)
    if res.silhouette_latent_2d is None:
        raise NotEnoughData(info["reason"] or "no latent embedding")
    last = ctx.scores.loc[ctx.scores["run_id"] == info["run_id"], "last_frame"]
    if not ctx.below_budget and (last.empty or not comparable.reached(float(last.fillna(0).max()), ctx.budget)):
        got = frames_text(float(last.fillna(0).max())) if not last.empty else "no evaluation"
        raise NotEnoughData(f"the t-SNE run {info['run_id']} reaches {got}; the claim is about {ctx.budget_text()}")
    ok = res.silhouette_latent_2d >= CLUSTER_THRESHOLD and res.silhouette_raw_2d < CLUSTER_THRESHOLD
    return (SUPPORTED if ok else REFUTED), (
        f"silhouette raw {res.silhouette_raw_2d:.3f}, latent {res.silhouette_latent_2d:.3f} (t-SNE 2-D; original "
        f"spaces: raw {res.silhouette_raw:.3f}, latent {res.silhouette_latent:.3f}); run {info['run_id']}")


def _batch(ctx: Context) -> tuple[str, str]:
    df = select.batch_size(ctx.scores, ctx.experiment_map)
    table = means(df, ["method", "batch_size"])
    series = {}
    for m in ("TACO", "DrQ-v2"):
        pts = sorted((int(k[1]), present(ctx, table, *k)) for k in table
                     if k[0] == m and get(ctx, table, *k) is not None)
        if len(pts) < 2:
            raise NotEnoughData(f"need {m} at >= 2 batch sizes (have {len(pts)})")
        series[m] = pts
    t_vals = [v for _, v in series["TACO"]]
    d_vals = [v for _, v in series["DrQ-v2"]]
    grows = all(b >= a for a, b in zip(t_vals, t_vals[1:])) and t_vals[-1] >= 1.1 * t_vals[0]
    flat = (max(d_vals) - min(d_vals)) <= 0.15 * np.mean(d_vals)
    ev = "; ".join(f"{m}: " + ", ".join(f"B{b} {v:.0f}" for b, v in pts) for m, pts in series.items())
    return (SUPPORTED if grows and flat else REFUTED), ev + f" (TACO grows: {grows}; DrQ-v2 flat: {flat})"


def _objectives(ctx: Context) -> tuple[str, str]:
    table = means(select.objective_removal(ctx.scores, ctx.experiment_map), ["label"])
    require(ctx, table, [("full",), ("no TACO",), ("no CURL",), ("no reward",)])
    full = present(ctx, table, "full")
    drops = {k: full - present(ctx, table, k) for k in ("no TACO", "no CURL", "no reward")}
    ok = drops["no TACO"] > 0 and drops["no TACO"] > max(drops["no CURL"], drops["no reward"])
    shown = dict(zip(drops, apart(list(drops.values()), 0)))
    return (SUPPORTED if ok else REFUTED), (f"full {full:.0f}; drops: "
                                            + ", ".join(f"{k} {v}" for k, v in shown.items()))


def _vs_repr(ctx: Context) -> tuple[str, str]:
    return vs_repr_rule(ctx, means(labelled(select.repr_objectives(ctx.scores, ctx.experiment_map)),
                                   ["task", "method"]))


def vs_repr_pairs(ctx: Context) -> list[tuple[tuple, tuple, str]]:
    """vs_repr_objectives' comparisons: TACO against each other objective where the paper has its value."""
    return [((t, "TACO"), (t, m), f"{t} vs {m}") for t in REPR_TASKS for m in ctx.paper.repr_others
            if ctx.paper.repr_value(t, m) is not None]


def vs_repr_rule(ctx: Context, table: dict[tuple, tuple[int, float]]) -> tuple[str, str]:
    """vs_repr_objectives on a (task, method) ``means`` table."""
    return universal(ctx, table, vs_repr_pairs(ctx))


def offline_scores(ctx: Context) -> pd.DataFrame:
    """Per-run scores for offline claims, at each run's own budget (its configured ``offline.updates``,
    analysis.scores.final_scores): ``reached`` when the run finished it. In an indicative reading every run
    with an evaluation counts at its latest evaluation, finished or not."""
    df = ctx.scores
    if df.empty:
        return df
    offline = df["dataset"].notna()
    reached = df["score"].notna() if ctx.below_budget else df["reached"].astype(bool)
    return df.assign(reached=(reached & offline).to_numpy(dtype=bool))


def _offline_table(ctx: Context, value: str = "score") -> tuple[dict, pd.DataFrame]:
    df = offline_runs(offline_scores(ctx), ctx.experiment_map)
    return means(df, ["task", "dataset", "method"], value), df


def _offline_gain(ctx: Context) -> tuple[str, str]:
    table, _ = _offline_table(ctx)
    return offline_gain_rule(ctx, table)


def offline_gain_pairs() -> list[tuple[tuple, tuple, str]]:
    """offline_gain's comparisons: X+TACO against X per task/dataset pair, X in TD3+BC and CQL."""
    return [((t, d, f"{x}+TACO"), (t, d, x), f"{t}/{d} {x}") for t in OFFLINE_TASKS
            for d in DatasetKind.values() for x in ("TD3+BC", "CQL")]


def offline_gain_rule(ctx: Context, table: dict[tuple, tuple[int, float]]) -> tuple[str, str]:
    """offline_gain on a (task, dataset, method) ``means`` table of returns."""
    return universal(ctx, table, offline_gain_pairs())


def _offline_average(ctx: Context) -> tuple[str, str]:
    table, df = _offline_table(ctx, "normalized")
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    require(ctx, table, [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED])
    matrices = {}
    for m in OFFLINE_AVERAGED:
        rows = df[(df["method"] == m) & df["reached"].astype(bool)]
        rows = rows.assign(task=rows["task"] + "/" + rows["dataset"])
        matrix, _ = score_matrix(rows, [f"{t}/{d}" for t, d in pairs], value="normalized")
        assert matrix is not None  # require() saw runs on every pair
        matrices[m] = matrix
    return offline_average_rule(ctx, matrices)


def offline_average_rule(ctx: Context, matrices: dict[str, np.ndarray]) -> tuple[str, str]:
    """offline_average on each printed method's (runs x 12 pairs) matrix of normalised scores: the verdict
    reads the bootstrap CI (``ctx.reps`` repetitions)."""
    ok, lines = True, []
    for m, p in offline_printed(ctx).items():
        mean, lo, hi = grand_mean_ci(matrices[m], ctx.reps, ctx.seed)
        inside = lo <= p <= hi
        ok &= inside
        mean_s, lo_s, hi_s, _ = apart([mean, lo, hi, float(p)], 1)
        lines.append(f"{m} {mean_s} [{lo_s}, {hi_s}] vs {p}{'' if inside else ' (outside)'}")
    return (SUPPORTED if ok else REFUTED), "; ".join(lines)


def _horizon(ctx: Context) -> tuple[str, str]:
    table = means(select.horizon(ctx.scores, ctx.experiment_map), ["task", "label"])
    pairs = [((t, "K=3"), (t, "K=1"), f"{t} K3>K1")
             for t in ("hopper_hop", "quadruped_walk", "acrobot_swingup", "reacher_hard")]
    pairs += [((t, "K=1"), (t, "K=3"), f"{t} K1>K3") for t in ("quadruped_run", "walker_run")]
    pairs += [((t, k), (t, "DrQ-v2"), f"{t} {k}>DrQ-v2") for t in DMC9 for k in ("K=1", "K=3")]
    return universal(ctx, table, pairs)


# the action-repeat sweep's grid (appendix B: action repeats 1, 2, 4; K from {1,3,5}), as the sweep runs it
ACTION_REPEATS = (1, 2, 4)
REPEAT_HORIZONS = (1, 3, 5)


def best_k_printed(paper: PaperData) -> dict[int, int]:
    """The action_repeat claim's best K at each action repeat, as the prose gives it (claim_numbers.csv)."""
    return {a: paper.claim_integer("action_repeat", f"best_k_at_repeat_{a}") for a in ACTION_REPEATS}


def _action_repeat_rule_text(paper: PaperData) -> str:
    (a1, k1), *rest = best_k_printed(paper).items()
    return (f"on hopper_hop the K in {{{','.join(map(str, REPEAT_HORIZONS))}}} with the highest mean is {k1} at "
            f"action repeat {a1}, " + " and ".join(f"{k} at {a}" for a, k in rest))


def _action_repeat(ctx: Context) -> tuple[str, str]:
    table = means(select.action_repeat(ctx.scores, ctx.experiment_map), ["label"])
    keys = [(f"AR={a}, K={k}",) for a in ACTION_REPEATS for k in REPEAT_HORIZONS]
    require(ctx, table, keys)
    best = {a: max(REPEAT_HORIZONS, key=lambda k: present(ctx, table, f"AR={a}, K={k}")) for a in ACTION_REPEATS}
    printed = best_k_printed(ctx.paper)
    ok = best == printed
    return (SUPPORTED if ok else REFUTED), ("best K: " + ", ".join(f"AR{a}: K={k}" for a, k in best.items())
                                            + " (paper: " + ", ".join(f"AR{a} K={k}" for a, k in printed.items())
                                            + ")")


def _action_dim(ctx: Context) -> tuple[str, str]:
    df = select.action_dim_runs(ctx.scores, ctx.experiment_map)
    table = means(df, ["dim"]) if not df.empty else {}
    have = sorted(k[0] for k in table if get(ctx, table, *k) is not None)
    mid = [d for d in have if 6 < d < 24]
    if 6 not in have or 24 not in have or not mid:
        raise NotEnoughData(f"need dims 6, 24 and one in between (have {have})")
    mids = [present(ctx, table, d) for d in mid]
    ok = (max(present(ctx, table, 6), present(ctx, table, 24)) < min(mids)
          and (max(mids) - min(mids)) <= 0.15 * np.mean(mids))
    return (SUPPORTED if ok else REFUTED), ", ".join(f"d={d} {get(ctx, table, d):.0f}" for d in have)


def paper_slowdown(paper: PaperData) -> float:
    """The speed claim's "about 3.6x slower" as the paper's prose gives it (repro_data/paper/claim_numbers.csv)."""
    return paper.claim_number("speed", "slowdown")


def _speed_rule_text(paper: PaperData) -> str:
    return (f"on one hardware, FPS(DrQ-v2 B256) / FPS(TACO B1024) within ±{SPEED_TOLERANCE:.0%} of "
            f"{paper_slowdown(paper):g}, and TACO's FPS decreases with batch size where measured (from `repro bench` "
            "files and runs of experiment 'speed'; other runs' FPS only in an indicative reading)")


def speed_printed(paper: PaperData) -> tuple[str, str]:
    """What the speed claim's evidence quotes from the packaged paper data: the prose's ratio with Tables 4-5's, and
    TACO's FPS per batch size."""
    taco = {b: paper.fps("TACO", b) for b in (256, 512, 1024)}
    drq = paper.fps("DrQ-v2", 256)
    return (f"(paper {paper_slowdown(paper):g}, from its table {drq:g}/{taco[1024]:g} = {drq / taco[1024]:.2f})",
            "(paper " + ", ".join(f"B{b} {v:g}" for b, v in taco.items()) + ")")


def _speed(ctx: Context) -> tuple[str, str]:
    meas = speed_measurements(ctx.results, fallback=ctx.below_budget)
    meas = meas[meas["speedup"] == "plain"]
    if meas.empty:
        raise NotEnoughData("no FPS measurements (bench/*.json or runs of experiment 'speed')")
    for hw, rows in meas.groupby("hardware"):
        fps = rows.groupby(["method", "batch_size"])["fps"].mean()
        if ("TACO", 1024) in fps.index and ("DrQ-v2", 256) in fps.index:
            ratio = fps[("DrQ-v2", 256)] / fps[("TACO", 1024)]
            taco = [(b, fps[("TACO", b)]) for b in (256, 512, 1024) if ("TACO", b) in fps.index]
            decreasing = all(a[1] > b[1] for a, b in zip(taco, taco[1:]))
            slowdown = paper_slowdown(ctx.paper)
            ok = (1 - SPEED_TOLERANCE) * slowdown <= ratio <= (1 + SPEED_TOLERANCE) * slowdown and decreasing
            printed_ratio, printed_fps = speed_printed(ctx.paper)
            ev = (f"on {hw}: ratio {ratio:.2f} {printed_ratio}; TACO FPS "
                  + ", ".join(f"B{b} {v}" for (b, _), v in zip(taco, apart([v for _, v in taco], 1)))
                  + f" {printed_fps}")
            return (SUPPORTED if ok else REFUTED), ev
    raise NotEnoughData("need TACO B1024 and DrQ-v2 B256 FPS measured on the same hardware")


def _seeds(ctx: Context) -> tuple[str, str]:
    df = select.online_main(ctx.scores, ctx.experiment_map)
    df = df[df["label"].isin(["TACO", "DrQ-v2"])] if not df.empty else df
    spread = seed_spread(df)
    return seed_robustness_rule(ctx, spread.set_index(["task", "label"]).to_dict("index"))


def seed_robustness_rule(ctx: Context, spread: dict[tuple, dict]) -> tuple[str, str]:
    """seed_robustness on per-cell spreads ((task, label) -> analysis.robustness.cell_spread)."""
    need = ctx.min_seeds
    got = {k: v for k, v in spread.items() if v["n"] >= need}
    tasks = [t for t in DMC9 if (t, "TACO") in got and (t, "DrQ-v2") in got]
    if len(tasks) < 9:
        raise NotEnoughData(f"need >= {need} seeds of TACO and DrQ-v2 on all 9 tasks (have {len(tasks)})")
    less = sum(got[(t, "TACO")]["std"] < got[(t, "DrQ-v2")]["std"] for t in tasks)
    broken = int(sum(v["broken"] for k, v in got.items() if k[1] == "DrQ-v2"))
    ok = less >= LESS_SPREAD_TASKS and broken >= 1
    taco_broken = int(sum(v["broken"] for k, v in got.items() if k[1] == "TACO"))
    return (SUPPORTED if ok else REFUTED), (f"TACO's std lower on {less}/9 tasks; DrQ-v2 broken seeds: {broken}; "
                                            f"TACO broken seeds: {taco_broken}")


def _manipulator(ctx: Context) -> tuple[str, str]:
    curves = select.manipulator(ctx.curves, ctx.experiment_map)
    solved = solved_counts(curves, ctx.budget)
    return manipulator_rule(ctx, solved.set_index("label").to_dict("index"))


def manipulator_rule(ctx: Context, s: dict[str, dict]) -> tuple[str, str]:
    """manipulator on solved counts per label (label -> runs, solved, last_frame; analysis.robustness)."""
    if "DrQ-v2" in s and s["DrQ-v2"]["solved"] > 0:
        return REFUTED, f"DrQ-v2 solves {int(s['DrQ-v2']['solved'])} seeds"
    if "TACO" not in s or "DrQ-v2" not in s or min(v["runs"] for v in s.values()) < ctx.min_seeds:
        raise NotEnoughData("need TACO and DrQ-v2 runs on manipulator_bring_ball")
    taco_frac = s["TACO"]["solved"] / s["TACO"]["runs"]
    ev = (f"TACO {int(s['TACO']['solved'])}/{int(s['TACO']['runs'])}, "
          f"DrQ-v2 0/{int(s['DrQ-v2']['runs'])} solved")
    if taco_frac >= SOLVED_FRACTION:
        return SUPPORTED, ev
    last = min(v["last_frame"] for v in s.values())
    if comparable.reached(last, ctx.budget):
        return REFUTED, ev
    raise NotEnoughData(ev + f"; runs reach only {frames_text(last)} of {ctx.budget_text()}")


# ---------------------------------------------------------------- the claims' cells (the power simulation's input)
CI_REPS = 300  # bootstrap repetitions per simulated draw where the verdict reads a CI (offline_average)
CI_SIMS = 100  # simulated draws of such a claim (each runs four bootstraps)


def _online_sources(ctx: Context, budget: float) -> list[CellSource]:
    """TACO's Table 1 cells and DrQ-v2's (its published per-seed values at ``budget``) on the nine tasks."""
    return table1_cells(ctx, DMC9) + [drqv2_cell(ctx, t, budget, (t, "DrQ-v2")) for t in DMC9]


def _published_sources(ctx: Context, budget: float) -> list[CellSource]:
    return table1_cells(ctx, DMC9) + published_fixed_cells(ctx, DMC9, budget)


def _manipulator_sources(ctx: Context, budget: float) -> list[CellSource]:
    return solved_cells(ctx, "manipulator", {"TACO": "taco_solved", "DrQ-v2": "drqv2_solved"})


def _judge_gain(ctx: Context, cells: Cells) -> tuple[str, str]:
    require(ctx, means_table(cells), [(t, m) for t in DMC9 for m in ("TACO", "DrQ-v2")])
    return avg_gain_rule(ctx, stacked(cells, [(t, "TACO") for t in DMC9]),
                         stacked(cells, [(t, "DrQ-v2") for t in DMC9]))


def _judge_published_gain(ctx: Context, cells: Cells) -> tuple[str, str]:
    require(ctx, means_table(cells), [(t, "TACO") for t in DMC9])
    ys = [cells[(t, "published")] for t in DMC9]
    if any(len(y) < ctx.min_seeds for y in ys):
        raise NotEnoughData(f"the published DrQ-v2 curves do not cover {ctx.budget_text()} on every task")
    return published_gain_rule(ctx, stacked(cells, [(t, "TACO") for t in DMC9]), ys)


def _judge_offline_average(ctx: Context, cells: Cells) -> tuple[str, str]:
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    require(ctx, means_table(cells), [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED])
    return offline_average_rule(ctx, {m: stacked(cells, [(t, d, m) for t, d in pairs]) for m in OFFLINE_AVERAGED})


def _judge_seeds(ctx: Context, cells: Cells) -> tuple[str, str]:
    return seed_robustness_rule(ctx, {k: cell_spread(v) for k, v in cells.items() if len(v)})


def _judge_manipulator(ctx: Context, cells: Cells) -> tuple[str, str]:
    return manipulator_rule(ctx, {k[0]: {"runs": len(v), "solved": int(v.sum()), "last_frame": float(ctx.budget)}
                                  for k, v in cells.items()})


def _on_table(rule: Callable[[Context, dict], tuple[str, str]]) -> Callable[[Context, Cells], tuple[str, str]]:
    return lambda ctx, cells: rule(ctx, means_table(cells))


# ---------------------------------------------------------------- the same verdicts, every draw at once
Draws = dict[Key, np.ndarray]  # every draw of the power simulation: cell -> (draws x its seeds)
# A claim's verdict in every draw at once, as its ``judge`` gives it draw by draw: an object array of verdicts,
# "" where a value the verdict compares lies within :data:`TIE` of its threshold (there the draw is judged one by
# one, so that a difference in the last bits of a whole-array sum cannot change a verdict).
BatchJudge = Callable[[Context, Draws], np.ndarray]
TIE = 1e-9  # relative distance from a threshold under which a draw is judged by ``judge`` itself

def _sims(draws: Draws) -> int:
    return next(iter(draws.values())).shape[0]


def _enough(ctx: Context, draws: Draws, key: Key) -> bool:
    """analysis.claims.get's test of a cell (its seeds are the same number in every draw)."""
    return key in draws and draws[key].shape[1] > 0 and draws[key].shape[1] >= ctx.min_seeds


def _near(a: np.ndarray, b: np.ndarray | float) -> np.ndarray:
    """Where ``a`` and ``b`` are within :data:`TIE` of each other (relative)."""
    return np.abs(a - b) <= TIE * (1.0 + np.abs(a) + np.abs(b))


def _verdicts(sims: int, supported: np.ndarray | bool, otherwise: str, unsure: np.ndarray | bool) -> np.ndarray:
    out = np.where(np.broadcast_to(supported, (sims,)), SUPPORTED, otherwise).astype(object)
    out[np.broadcast_to(unsure, (sims,))] = ""
    return out


def _all(sims: int, verdict: str) -> np.ndarray:
    return np.full(sims, verdict, dtype=object)


def _stacked_draws(draws: Draws, keys: Sequence[Key]) -> np.ndarray:
    """:func:`stacked` of every draw: (draws x seeds x cells)."""
    k = min(draws[key].shape[1] for key in keys)
    return np.stack([draws[key][:, :k] for key in keys], axis=2)


def universal_batch(pairs: Callable[[Context], Sequence[tuple[Key, Key, str]]]) -> BatchJudge:
    """analysis.claims.universal over a means table, every draw at once: refuted where a pair present fails,
    else not enough data where one is missing, else supported."""

    def judge(ctx: Context, draws: Draws) -> np.ndarray:
        sims = _sims(draws)
        fail, unsure, missing = np.zeros(sims, bool), np.zeros(sims, bool), False
        for a, b, _ in pairs(ctx):
            if not (_enough(ctx, draws, a) and _enough(ctx, draws, b)):
                missing = True
                continue
            va, vb = draws[a].mean(axis=1), draws[b].mean(axis=1)
            fail |= ~(va > vb)
            unsure |= _near(va, vb)
        out = np.where(fail, REFUTED, NO_DATA if missing else SUPPORTED).astype(object)
        out[unsure] = ""
        return out

    return judge


def _gain_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """:func:`_judge_gain` (analysis.claims.avg_gain_rule) in every draw."""
    sims = _sims(draws)
    taco, drq = [(t, "TACO") for t in DMC9], [(t, "DrQ-v2") for t in DMC9]
    if not all(_enough(ctx, draws, k) for k in taco + drq):
        return _all(sims, NO_DATA)
    r = bs.RATIO_OF_MEANS.vector(_stacked_draws(draws, taco), _stacked_draws(draws, drq))[:, 0]
    bar = gain_bar(ctx.paper)
    return _verdicts(sims, r >= bar, REFUTED, _near(r, bar))


def _published_gain_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """:func:`_judge_published_gain` (analysis.claims.published_gain_rule) in every draw."""
    sims = _sims(draws)
    taco = [(t, "TACO") for t in DMC9]
    if not all(_enough(ctx, draws, k) for k in taco):
        return _all(sims, NO_DATA)
    ys = [np.ascontiguousarray(draws[(t, "published")], dtype=float) for t in DMC9]
    if any(y.shape[1] < ctx.min_seeds for y in ys):
        return _all(sims, NO_DATA)
    r = bs.RATIO_TO_TASK_MEANS.vector(_stacked_draws(draws, taco), *(y[:, :, None] for y in ys))[:, 0]
    bar = gain_bar(ctx.paper)
    return _verdicts(sims, r >= bar, REFUTED, _near(r, bar))


def _model_based_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.beats_model_based_rule in every draw (a baseline without cells: Table 1's value)."""
    sims = _sims(draws)
    if not all(_enough(ctx, draws, (t, "TACO")) for t in DMC9):
        return _all(sims, NO_DATA)
    wins, unsure = np.zeros(sims, int), np.zeros(sims, bool)
    for t in DMC9:
        base = []
        for m in MODEL_BASED:
            if _enough(ctx, draws, (t, m)):
                base.append(draws[(t, m)].mean(axis=1))
            else:
                printed = ctx.paper.online_value(t, m)
                assert printed is not None  # Table 1 has both baselines on every DMC task
                base.append(np.full(sims, float(printed[0])))
        best = np.max(np.stack(base), axis=0)
        taco = draws[(t, "TACO")].mean(axis=1)
        wins += taco > best
        unsure |= _near(taco, best)
    return _verdicts(sims, wins >= MODEL_BASED_WINS, REFUTED, unsure)


def _seeds_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.seed_robustness_rule on every draw's cell spreads (analysis.robustness.cell_spread)."""
    sims = _sims(draws)
    got = {k: v for k, v in draws.items() if v.shape[1] > 0 and v.shape[1] >= ctx.min_seeds}
    tasks = [t for t in DMC9 if (t, "TACO") in got and (t, "DrQ-v2") in got]
    if len(tasks) < 9:
        return _all(sims, NO_DATA)
    less, broken, unsure = np.zeros(sims, int), np.zeros(sims, int), np.zeros(sims, bool)
    for t in tasks:
        a, b = got[(t, "TACO")], got[(t, "DrQ-v2")]
        sa = a.std(ddof=1, axis=1) if a.shape[1] > 1 else np.full(sims, math.nan)
        sb = b.std(ddof=1, axis=1) if b.shape[1] > 1 else np.full(sims, math.nan)
        less += sa < sb
        unsure |= _near(sa, sb)
    for k, v in got.items():
        if k[1] != "DrQ-v2":
            continue
        med = np.median(v, axis=1)
        half = BROKEN_FRACTION * med
        broken += np.where(med > 0, (v < half[:, None]).sum(axis=1), 0)
        unsure |= _near(med, 0.0) | _near(v, half[:, None]).any(axis=1)
    return _verdicts(sims, (less >= LESS_SPREAD_TASKS) & (broken >= 1), REFUTED, unsure)


def _manipulator_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.manipulator_rule on every draw's solved counts (values 0 or 1: exact sums)."""
    sims = _sims(draws)
    runs = {k[0]: v.shape[1] for k, v in draws.items()}
    solved = {k[0]: v.sum(axis=1) for k, v in draws.items()}
    drq_solves = solved["DrQ-v2"] > 0 if "DrQ-v2" in solved else np.zeros(sims, bool)
    if "TACO" not in runs or "DrQ-v2" not in runs or min(runs.values()) < ctx.min_seeds:
        out = _all(sims, NO_DATA)
    else:
        # every cell's last frame is the budget in the simulation: short of a third of TACO's seeds is refuted
        out = np.where(solved["TACO"] / runs["TACO"] >= SOLVED_FRACTION, SUPPORTED, REFUTED).astype(object)
    out[drq_solves] = REFUTED
    return out


def _offline_average_batch(ctx: Context, draws: Draws) -> np.ndarray:
    """analysis.claims.offline_average_rule in every draw: each printed average inside its method's bootstrap CI
    (the same bootstrap indices: they depend only on the shapes and the random state, so they are drawn once; the
    means as one product, :func:`analysis.bootstrap.mean_intervals_many`, so a draw whose bound lies within
    :data:`TIE` of the printed average is judged by the rule)."""
    sims = _sims(draws)
    pairs = [(t, d) for t in OFFLINE_TASKS for d in DatasetKind.values()]
    keys = [(t, d, m) for t, d in pairs for m in OFFLINE_AVERAGED]
    if not all(_enough(ctx, draws, k) for k in keys):
        return _all(sims, NO_DATA)
    ok, unsure = np.ones(sims, bool), np.zeros(sims, bool)
    for m, p in offline_printed(ctx).items():
        lo, hi = bs.mean_intervals_many(_stacked_draws(draws, [(t, d, m) for t, d in pairs]), ctx.reps, ctx.seed)
        ok &= (lo <= p) & (p <= hi)
        unsure |= _near(lo, p) | _near(hi, p)
    return _verdicts(sims, ok, REFUTED, unsure)


def _online_observed(ctx: Context) -> Cells:
    return observed_cells(online_rows(ctx), ["task", "method"])


def _offline_observed(ctx: Context) -> Cells:
    return observed_cells(offline_runs(offline_scores(ctx), ctx.experiment_map), ["task", "dataset", "method"],
                          "normalized")


def _seeds_observed(ctx: Context) -> Cells:
    df = select.online_main(ctx.scores, ctx.experiment_map)
    return observed_cells(df[df["label"].isin(["TACO", "DrQ-v2"])] if not df.empty else df, ["task", "label"])


def _repr_observed(ctx: Context) -> Cells:
    return observed_cells(labelled(select.repr_objectives(ctx.scores, ctx.experiment_map)), ["task", "method"])


_OFFLINE_NOTE = ("the rule compares returns; the cells are Table 3's normalised scores (100 x return / the reference "
                 "return, increasing in the return), so every comparison agrees")
_FIGURE_ONLY = "the paper gives {} only as a figure ({}), with no numbers"


def _manipulator_counts(paper: PaperData) -> tuple[float, float, float]:
    """Appendix G's (TACO's solved seeds, DrQ-v2's, seeds per method), from its prose (claim_numbers.csv)."""
    number = paper.claim_number
    return number("manipulator", "taco_solved"), number("manipulator", "drqv2_solved"), number("manipulator", "seeds")


def _manipulator_rule_text(paper: PaperData) -> str:
    taco, _, seeds = _manipulator_counts(paper)
    return ("within the budget (30M frames) TACO solves (an eval return >= 500) at least a third of its seeds "
            f"(paper {taco:g}/{seeds:g}) and DrQ-v2 none")


def _manipulator_note(paper: PaperData) -> str:
    _, drq, seeds = _manipulator_counts(paper)
    return (f"DrQ-v2's {drq:g} of {seeds:g} taken as a solve probability of {drq / seeds:g} (its 95% upper bound is "
            f"{solve_upper_bound(int(drq), int(seeds)):.0%}): optimistic")

# ---------------------------------------------------------------- the claims
# Every claim of claims.csv, in its order, each once (tests/test_claim_sources.py).
SPECS: tuple[ClaimSpec, ...] = (
    ClaimSpec("online_avg_gain", _online_avg_gain,
              _gain_rule_text,
              Simulation(_online_sources, _judge_gain, _online_observed, DMC9, batch=_gain_batch)),
    ClaimSpec(PUBLISHED_GAIN_ID, _online_avg_gain_published, _published_gain_rule_text,
              Simulation(_published_sources, _judge_published_gain, _online_observed, DMC9,
                         notes=("DrQ-v2 is the published curves as published (fixed data, as `repro claims` reads "
                                "them)",), batch=_published_gain_batch),
              reading_of="online_avg_gain",
              note=f"read against DrQ-v2 as published by its authors, not against your DrQ-v2 runs: {SOURCE_TEXT}",
              audit=("online_gain_vs_published",)),
    ClaimSpec("online_beats_drqv2_all", _beats_drqv2,
              "TACO mean > DrQ-v2 mean on each of the 9 tasks",
              Simulation(_online_sources, _on_table(beats_drqv2_rule), _online_observed, DMC9,
                         batch=universal_batch(lambda c: beats_drqv2_pairs()))),
    ClaimSpec("online_beats_model_based", _beats_model_based,
              f"TACO mean > both DreamerV3 and TD-MPC on >= {MODEL_BASED_WINS} of 9 tasks (baselines from runs, "
              "else the paper's Table 1)",
              Simulation(lambda ctx, budget: table1_cells(ctx, DMC9), _on_table(beats_model_based_rule),
                         _online_observed, DMC9,
                         notes=("DreamerV3 and TD-MPC are Table 1's printed means (not rerun by any sweep), as the "
                                "rule reads them",), batch=_model_based_batch)),
    ClaimSpec("reacher_speed", _reacher_speed, _reacher_rule_text,
              not_simulated="its rule reads TACO's and DrQ-v2's mean learning curves up to 1.5M frames; the paper "
                            "gives TACO's curve only as a figure (F4), with no per-seed or per-frame numbers"),
    ClaimSpec("longer_training", _longer,
              "TACO mean > DrQ-v2 mean at the last common frame (>= the budget, 2M) on quadruped_run, "
              "hopper_hop, walker_run, cheetah_run",
              not_simulated="its rule reads both methods at 2M frames; the paper gives those only as learning-curve "
                            "figures (F4), with no numbers at 2M"),
    ClaimSpec("metaworld", _metaworld,
              "TACO mean success > each baseline's (DrQ-v2; A-LIX if run) on each of the 6 tasks at the budget",
              not_simulated="the paper gives Meta-world success rates only as figures (F5), with no mean or std per "
                            "task"),
    ClaimSpec("action_repr_gain", _action_repr_gain,
              "TACO mean > TACO w/o action repr mean on every task of the action_repr sweep (named: "
              "quadruped_run, hopper_hop, reacher_hard)",
              not_simulated="the paper gives the gains as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("no_action_repr_vs_drqv2", _no_repr_vs_drqv2,
              "TACO w/o action repr beats DrQ-v2 on quadruped_run and reacher_hard, and is within "
              f"±{COMPARABLE_WITHIN:.0%} of DrQ-v2 on the other tasks of the sweep",
              not_simulated="the paper gives these as percentages of a bar figure (F3) with no std over seeds"),
    ClaimSpec("tsne_clusters", _tsne,
              f"silhouette of the 4 centroid labels on the t-SNE embedding: latent >= {CLUSTER_THRESHOLD} "
              f"and raw < {CLUSTER_THRESHOLD}",
              not_simulated="one trained agent and a t-SNE embedding: not a statistic over seeds"),
    ClaimSpec("batch_size", _batch,
              "on quadruped_run TACO's mean is non-decreasing in batch size and >= 10% higher at the largest "
              "than at the smallest; DrQ-v2's range is <= 15% of its mean",
              not_simulated=_FIGURE_ONLY.format("the batch-size results", "F7a")),
    ClaimSpec("objective_removal", _objectives,
              "on quadruped_run the drop full - no TACO is positive and larger than the drops of no "
              "CURL and no reward",
              not_simulated="the paper gives the ablation only as a figure (F7b), with no numbers"),
    ClaimSpec("vs_repr_objectives", _vs_repr,
              "TACO mean > each other objective of Table 2 (each of its methods but TACO and DrQ-v2; where the "
              "paper has its value) on each of the 5 tasks",
              Simulation(lambda ctx, budget: table2_cells(ctx, REPR_TASKS), _on_table(vs_repr_rule), _repr_observed,
                         REPR_TASKS, batch=universal_batch(vs_repr_pairs))),
    ClaimSpec("offline_gain", _offline_gain,
              "return of X+TACO > X for X in TD3+BC, CQL on each of the 12 task/dataset pairs",
              Simulation(lambda ctx, budget: table3_cells(ctx, OFFLINE_AVERAGED), _on_table(offline_gain_rule),
                         _offline_observed, OFFLINE_TASKS, notes=(_OFFLINE_NOTE,),
                         batch=universal_batch(lambda c: offline_gain_pairs()))),
    ClaimSpec("offline_average", _offline_average,
              "each printed average of Table 3's average row (TD3+BC+TACO, TD3+BC, CQL+TACO, CQL; "
              "repro_data/paper/offline_average.csv) lies in the 95% CI of the reproduced average normalised score "
              "over the 12 pairs",
              Simulation(lambda ctx, budget: table3_cells(ctx, OFFLINE_AVERAGED), _judge_offline_average,
                         _offline_observed, OFFLINE_TASKS, sims=CI_SIMS, reps=CI_REPS,
                         batch=_offline_average_batch)),
    ClaimSpec("horizon_choice", _horizon,
              "K=3 > K=1 on hopper_hop, quadruped_walk, acrobot_swingup, reacher_hard; K=1 > K=3 on "
              "quadruped_run, walker_run; K=1 and K=3 > DrQ-v2 on all 9 tasks",
              not_simulated=_FIGURE_ONLY.format("K=1 and K=3", "F8")),
    ClaimSpec("action_repeat", _action_repeat, _action_repeat_rule_text,
              not_simulated=_FIGURE_ONLY.format("the action-repeat results", "F9")),
    ClaimSpec("action_dim", _action_dim,
              "on quadruped_run the means at dims 6 and 24 are below every intermediate dim's, and the "
              "intermediate dims' range is <= 15% of their mean",
              not_simulated=_FIGURE_ONLY.format("the latent-dimension results", "appendix E")),
    ClaimSpec("speed", _speed, _speed_rule_text,
              not_simulated="a timing on your hardware (`repro bench`), not a statistic over seeds"),
    ClaimSpec("seed_robustness", _seeds,
              f"TACO's std over seeds < DrQ-v2's on >= {LESS_SPREAD_TASKS} of the 9 tasks, and DrQ-v2 has >= 1 broken "
              "seed (below half its cell's median)",
              Simulation(_online_sources, _judge_seeds, _seeds_observed, DMC9,
                         notes=("a broken seed is one below half its cell's median: normal cells almost never have "
                                "one, so DrQ-v2's published values carry the claim's second half",),
                         batch=_seeds_batch)),
    ClaimSpec("manipulator", _manipulator, _manipulator_rule_text,
              Simulation(_manipulator_sources, _judge_manipulator, None, ("manipulator_bring_ball",),
                         notes=(_manipulator_note, "not conditioned on runs (the rule reads learning curves)"),
                         batch=_manipulator_batch)),
)
SPEC_OF = {s.id: s for s in SPECS}
if len(SPEC_OF) != len(SPECS):  # a claim defined twice: one of its definitions would be silently dropped
    raise ValueError(f"claims defined twice: {sorted({s.id for s in SPECS if sum(t.id == s.id for t in SPECS) > 1})}")


def claim_specs(paper: PaperData) -> list[ClaimSpec]:
    """The claims every reader lists (`repro claims`, `repro plan --claims`, the report): one spec per claim of
    ``paper``'s claims.csv in its order, each followed by its other readings. Raises ValueError when a claim of
    claims.csv has no spec or a spec judges a claim it does not have."""
    ids = list(paper.claims["id"])
    missing = [i for i in ids if i not in SPEC_OF]
    extra = [s.id for s in SPECS if s.claim_id not in ids]
    if missing or extra:
        raise ValueError(f"claims.csv and analysis.claims.SPECS disagree: no spec for {missing}; no claim for {extra}")
    return [s for i in ids for s in [SPEC_OF[i], *(r for r in SPECS if r.reading_of == i)]]


# ---------------------------------------------------------------- entry points
def _claim_context(ctx: Context, spec: ClaimBudget, budget: int | None, below: bool) -> Context:
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


def _short_of_budget(ctx: Context, spec: ClaimBudget) -> str | None:
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


def _judge(ctx: Context, fn: Check) -> tuple[str, str]:
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


def _indicative(ctx: Context, spec: ClaimBudget, fn: Check) -> tuple[str, str]:
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
    verdict, evidence = _judge(_claim_context(ctx, spec, budget, below=True), fn)
    if verdict == NO_DATA:
        return "", f"no indicative reading at {where}: {evidence}"
    words = budget_words(ctx.paper, spec.id, spec.holds if verdict == SUPPORTED else spec.fails)
    label = f"indicative: {words} ({where}, {seed_counts(runs)})"
    return label, f"indicative reading at {where}, below the claim's budget or seed count: {evidence}"


def evaluate_claims(ctx: Context) -> list[Verdict]:
    """One verdict per claim of :func:`claim_specs` (claims.csv's order, the reading of online_avg_gain against the
    published DrQ-v2 curves after it), each at the claim's own budget."""
    budgets = load_budgets()
    text = dict(zip(ctx.paper.claims["id"], ctx.paper.claims["claim"]))
    out = []
    for spec in claim_specs(ctx.paper):
        claim = text[spec.claim_id] + (f" [{spec.note}]" if spec.note else "")
        budget = budgets.get(spec.claim_id)
        if budget is None:
            out.append(Verdict(spec.id, claim, NO_DATA, "no budget for this claim in claim_budgets.csv",
                               spec.rule_text(ctx.paper)))
            continue
        verdict, evidence, label = _reading(ctx, budget, _short_of_budget(ctx, budget), spec.check)
        runs = claim_runs(ctx.scores, budget, ctx.experiment_map, offline=budget.kind == "offline_updates")
        out.append(Verdict(spec.id, claim, verdict, evidence, spec.rule_text(ctx.paper), budget.column(runs),
                           max(budget.min_seeds, ctx.min_seeds), label))
    return out


def _reading(ctx: Context, spec: ClaimBudget, short: str | None, fn: Check) -> tuple[str, str, str]:
    """(verdict, evidence, indicative label) of claim function ``fn`` under the budget rule: no data when the
    runs fall ``short`` of the claim's budget (with a labelled indicative reading on request), else judged."""
    if short is not None:
        verdict, evidence = NO_DATA, short
    else:
        verdict, evidence = _judge(_claim_context(ctx, spec, spec.budget, below=False), fn)
    evidence = f"at {spec.text()}: {evidence}"
    label = ""
    if verdict == NO_DATA and ctx.indicative:
        label, extra = _indicative(ctx, spec, fn)
        evidence = f"{evidence}. {extra}"
    return verdict, evidence, label


def verdict_counts(verdicts: Sequence[Verdict]) -> str:
    """'21 rows (...): 2 supported, 1 refuted, 18 not enough data (5 with an indicative reading, not a verdict)': the
    counts add up to the rows of the claims table, the reading of online_avg_gain against the published DrQ-v2
    curves (a row of its own) among them, named."""
    counts = {k: sum(v.verdict == k for v in verdicts) for k in (SUPPORTED, REFUTED, NO_DATA)}
    text = ", ".join(f"{counts[k]} {k}" for k in (SUPPORTED, REFUTED, NO_DATA))
    n_ind = sum(bool(v.indicative) for v in verdicts)
    text += f" ({n_ind} with an indicative reading, not a verdict)" if n_ind else ""
    readings = [v for v in verdicts if v.id == PUBLISHED_GAIN_ID]
    what = (f"the paper's {len(verdicts) - len(readings)} claims and online_avg_gain read against the published "
            "DrQ-v2 curves" if readings else f"the paper's {len(verdicts)} claims")
    return f"{len(verdicts)} rows ({what}): {text}"


def claims_frame(verdicts: Sequence[Verdict]) -> pd.DataFrame:
    """The display table of the claims: Claim, Verdict (or indicative label), Budget, Seeds, Numbers, Rule."""
    return pd.DataFrame({"Claim": [v.id for v in verdicts], "Verdict": [v.shown for v in verdicts],
                         "Budget": [v.budget for v in verdicts],
                         "Seeds": [f">= {v.min_seeds}" if v.min_seeds else "" for v in verdicts],
                         "Numbers": [v.evidence for v in verdicts], "Rule": [v.rule for v in verdicts]})


def write_claims(ctx: Context, verdicts: Sequence[Verdict]):
    """Write ``claims.csv/.md/.tex`` to ``ctx.out_dir``."""
    raw = pd.DataFrame([v.__dict__ for v in verdicts])
    caption = f"Verdict on each claim of the paper from the reproduced runs ({verdict_counts(verdicts)})."
    notes = ["Each claim is judged at its own budget (Budget: environment frames = agent steps x action repeat, the "
             "repeat of the claim's runs beside them, the paper's where there are none; offline, gradient "
             "updates) with at least the seeds per cell in Seeds "
             "(analysis/claim_budgets.csv), only from runs that reached that budget; verdicts compare means "
             "with the tolerances in the Rule column; CIs are 95% stratified-bootstrap (rliable)."]
    if any(v.indicative for v in verdicts):
        notes.append("An 'indicative' entry is a reading below the claim's budget or seed count, asked for "
                     "with --indicative: it is not a verdict and counts as not enough data.")
    return write_table(ctx.out_dir, "claims", raw, caption, claims_frame(verdicts), notes)
