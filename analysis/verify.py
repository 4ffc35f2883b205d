"""`repro verify`'s judgement: does this installation learn as the DrQ-v2 authors' code did?

The runs are those of experiment ``verify`` (``sweeps/verify.yaml``) under a results root; the reference is the DrQ-v2
authors' published per-seed curves (:mod:`analysis.calibration` reads them). One verdict per task, method and
variant (docs/verification.md says the same in prose):

* **DrQ-v2: within the published band.** At every published evaluation frame ``f`` (after 0) that every seed of the
  cell reaches, the cell's statistic is the mean over its seeds of the evaluation return at ``f``. The published band
  at ``f`` is ``[min_f - k·sd_f, max_f + k·sd_f]``: the lowest and highest published seed at ``f``, widened by
  :data:`BAND_SD` (``k``) times the published seeds' standard deviation there. Verdict: ``learns as published`` when
  the statistic is inside the band at every judged frame, ``below the published band`` when it is under it at one
  (``above ...`` when over it at one and under it at none). The verdict needs every seed at the task's verdict frame
  (:data:`RULES`: 60K frames on cartpole_balance, where every published seed is 963-995); before that, or with fewer
  than ``min_seeds`` seeds: ``not enough data``, never a verdict.
* **False-alarm rate** of that rule for a correct pipeline, from the published seeds themselves: every set of ``n``
  published seeds (``n`` = the cell's seeds) is judged as if it were the user's runs, against the band made from the
  other published seeds at the same frames; the rate is the share of those sets the rule calls outside the band.
* **Any other method (TACO): learned.** At the last published frame ``f`` its seeds all reach (at least the task's
  TACO frame, :data:`RULES`), the mean over its seeds must be at least ``R + LEARNED_SHARE·(P_f - R)``: ``R`` the
  task's random-policy return (uniform actions, :func:`repro.envs.dmc.random_policy_returns`), ``P_f`` the
  published DrQ-v2 mean at ``f``. Its curve is drawn beside DrQ-v2's and its frames are shown against the band
  (for information: TACO at a batch of 256 is not DrQ-v2).
* **Not comparable.** A cell whose environment differs from the published curves' (analysis/comparable.py's
  ``env_difference``: episodes of 1000 frames, action repeat 2, 84x84 frames, 3 stacked, the task's camera, no
  distracting dimension; e.g.
  ``--set profile=tiny``'s 100-frame episodes, whose returns are about a tenth of a 1000-frame episode's) is ``not
  comparable``, never a verdict; the difference is named in the verdict table, the frames table and the figure.
* **What the table states.** Every verdict row carries its statistic, the band (or DrQ-v2's threshold for other
  methods) and the false-alarm rate; where there is no number, "n/a" with the reason.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis import comparable
from analysis.calibration import SOURCE_TEXT, packaged_published, values_at
from analysis.claim_budget import frames_text
from analysis.comparable import env_difference
from analysis.io import atomic_write_text
from analysis.load import Results, read_config
from analysis.stats import poi_interval
from analysis.tables import TableOutput, fmt_num, write_table
from repro.envs.dmc import random_policy_returns
from repro.envs.registry import get_task
from repro.runs import runformat
from repro.runs.health import at_bound, read_rows

EXPERIMENT = "verify"  # sweeps/verify.yaml's experiment
BASELINE = "DrQ-v2"  # the method judged against the published band
BAND_SD = 1.0  # k: the band is the published seeds' range widened by k standard deviations at each frame
LEARNED_SHARE = 0.5  # TACO "learned": at least half-way from the random policy's return to the published mean
RANDOM_EPISODES = 10  # episodes of the random-policy reference
MIN_SEEDS = 1  # the band is a per-seed band: one seed is judged (the false-alarm rate says what that is worth)

LEARNS, BELOW, ABOVE = "learns as published", "below the published band", "above the published band"
LEARNED, NOT_LEARNED = "learned", "not learned"
NOT_ENOUGH = "not enough data"
NOT_COMPARABLE = "not comparable"  # the runs' environment differs from the published curves' (never a verdict)
INSIDE, UNDER, OVER = "inside", "below", "above"


@dataclass(frozen=True)
class TaskRule:
    """What the check needs on one task: every DrQ-v2 seed at ``verdict_frame``; TACO at ``learned_frame``."""

    task: str
    verdict_frame: int
    learned_frame: int


# The environment of the published curves: DrQ-v2's DMC settings, the paper's; a run whose config differs is "not
# comparable" (analysis/comparable.py's env_difference: the one rule for tables, figures and this check).
PUBLISHED_ENV_TEXT = ("the published settings (1000-frame episodes, action repeat 2, 84x84 pixels, 3 stacked frames, "
                      "the task's camera, no distracting dimension)")
RULES: dict[str, TaskRule] = {r.task: r for r in (
    # every published seed is 963-995 at 60K frames; a pipeline that does not learn stays far under the band at
    # 40K and 60K (docs/verification.md)
    TaskRule("cartpole_balance", 60_000, 40_000),
)}


@dataclass
class FrameRow:
    """One judged frame of one cell."""

    task: str
    method: str
    variant: str
    frame: int
    n: int
    mean: float
    low: float  # lowest seed
    high: float  # highest seed
    published_n: int
    published_mean: float
    published_min: float
    published_max: float
    band_low: float
    band_high: float
    position: str  # inside | below | above


@dataclass
class AdvantageRow:
    """One judged frame of a method other than DrQ-v2 against the published DrQ-v2 seeds: the probability that one
    of its seeds beats one published seed (rliable's probability of improvement, ties a half) with its 95%
    stratified-bootstrap interval (analysis/stats.py). An observation at a small budget, not a verdict on a claim."""

    task: str
    method: str
    variant: str
    frame: int
    n: int  # the method's seeds at the frame
    published_n: int
    poi: float
    poi_low: float
    poi_high: float


@dataclass
class VerdictRow:
    """The verdict of one cell (task, method, variant)."""

    task: str
    method: str
    variant: str
    seeds: int
    reached: float  # the last frame every seed reached
    verdict: str
    rule: str
    false_alarm: float = math.nan
    threshold: float = math.nan  # learned: the return to reach
    random_return: float = math.nan
    note: str = ""
    statistic: str = ""  # what the rule reads, at each frame it reads (or "n/a: why")
    band: str = ""  # DrQ-v2: the published band at those frames; other methods: the learned threshold
    environment: str = ""  # how the runs' environment differs from the published curves' ("" when it does not)
    health: str = ""  # the seeds whose actor is at the bound, saturated or not yet (repro/runs/health.py)
    health_logged: bool = True  # every seed's train.csv logs actor_saturated (runs before issue 49 do not)
    repeats: tuple[int, ...] = ()  # the action repeats of the cell's runs (shown beside the frames reached)
    frames: list[FrameRow] = field(default_factory=list, repr=False)
    advantage: list[AdvantageRow] = field(default_factory=list, repr=False)  # methods other than DrQ-v2

    @property
    def judged(self) -> bool:
        return self.verdict not in (NOT_ENOUGH, NOT_COMPARABLE)


def band(values: np.ndarray, k: float = BAND_SD) -> tuple[float, float]:
    """The published band of one frame: the seeds' range widened by ``k`` standard deviations (ddof 1)."""
    sd = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
    return float(np.min(values)) - k * sd, float(np.max(values)) + k * sd


def position(value: float, low: float, high: float) -> str:
    return UNDER if value < low else OVER if value > high else INSIDE


def false_alarm_rate(published: np.ndarray, n: int, k: float = BAND_SD) -> float:
    """The rule's false-alarm rate for ``n`` seeds of a correct pipeline: ``published`` is (seeds, frames) at the
    judged frames; every set of ``n`` published seeds is judged against the band of the others. NaN when fewer than
    ``n + 2`` published seeds (a band needs two seeds)."""
    seeds = published.shape[0]
    if published.ndim != 2 or seeds < n + 2 or n < 1:
        return math.nan
    outside = total = 0
    for chosen in itertools.combinations(range(seeds), n):
        rest = published[[i for i in range(seeds) if i not in chosen]]
        mean = published[list(chosen)].mean(axis=0)
        bands = [band(rest[:, j], k) for j in range(published.shape[1])]
        outside += any(position(float(m), lo, hi) != INSIDE for m, (lo, hi) in zip(mean, bands))
        total += 1
    return outside / total


@functools.cache
def random_return(task: str, episodes: int = RANDOM_EPISODES) -> float:
    """The mean return of the uniform random policy on ``task`` (action repeat 2, seeds 0..episodes-1)."""
    return float(np.mean(random_policy_returns(get_task(task), episodes)))


def published_frames(task: str, upto: float) -> list[int]:
    """The published evaluation frames of ``task`` in (0, upto]."""
    ev = packaged_published().eval
    frames = ev.loc[ev["task"] == task, "frame"].dropna().unique()
    return sorted(int(f) for f in frames if 0 < f <= upto)


def published_matrix(task: str, frames: Sequence[int], published: Results | None = None) -> np.ndarray:
    """The published seeds' returns at ``frames``: (seeds, frames), seeds in the file's order."""
    published = packaged_published() if published is None else published
    cols = [values_at(published, f, task).sort_values("seed")["value"].to_numpy(dtype=float) for f in frames]
    return np.stack(cols, axis=1) if cols else np.empty((0, 0))


def verify_cells(results: Results) -> pd.DataFrame:
    """The runs of experiment ``verify`` on a task with a rule: one row per run."""
    runs = results.runs
    if runs.empty:
        return runs
    keep = (runs["experiment"] == EXPERIMENT) & runs["task"].isin(list(RULES)) & runs["dataset"].isna()
    return runs[keep]


@dataclass(frozen=True, eq=False)
class Judgement:
    """`repro verify`'s section of a report: the verdicts and the runs they judged (one row per run of
    :func:`verify_cells`), which the figure (paper_figures/verify_plot.py) draws without judging again."""

    rows: tuple[VerdictRow, ...]
    cells: pd.DataFrame


def judgement(results: Results, min_seeds: int = MIN_SEEDS, published: Results | None = None,
              random_returns: dict[str, float] | None = None) -> Judgement:
    """The verify runs under ``results`` and one :class:`VerdictRow` per task, method and variant of them.

    ``random_returns`` (task -> return) replaces the simulated random-policy reference (tests)."""
    cells = verify_cells(results)
    return Judgement(tuple(_judge_cells(results, cells, min_seeds, published, random_returns)), cells)


def judge(results: Results, min_seeds: int = MIN_SEEDS, published: Results | None = None,
          random_returns: dict[str, float] | None = None) -> list[VerdictRow]:
    """One :class:`VerdictRow` per task, method and variant of the ``verify`` runs under ``results``
    (:func:`judgement`'s rows)."""
    return list(judgement(results, min_seeds, published, random_returns).rows)


def _judge_cells(results: Results, runs: pd.DataFrame, min_seeds: int, published: Results | None,
                 random_returns: dict[str, float] | None) -> list[VerdictRow]:
    """The verdicts of the verify runs ``runs`` (:func:`verify_cells` of ``results``)."""
    published = packaged_published() if published is None else published
    rows: list[VerdictRow] = []
    if runs.empty:
        return rows
    for (task, method, variant), cell in runs.groupby(["task", "method", "variant"], sort=True):
        rule = RULES[task]
        ids = cell["run_id"]
        cell_results = Results(results.root, cell, results.eval[results.eval["run_id"].isin(ids)])
        last = pd.to_numeric(cell["last_frame"], errors="coerce")
        reached = float(last.min()) if last.notna().all() and len(last) else 0.0
        frames = published_frames(task, reached)
        frame_rows = _frame_rows(cell_results, published, task, str(method), str(variant), frames)
        base = dict(task=task, method=str(method), variant=str(variant), seeds=len(cell), reached=reached,
                    repeats=tuple(sorted({int(r) for r in cell["action_repeat"].dropna()})),
                    frames=frame_rows, environment=cell_environment(results.root, cell, task),
                    **cell_health(results.root, cell))
        if method == BASELINE:
            row = _baseline_verdict(base, rule, published, frames, frame_rows, min_seeds)
        else:
            given = (random_returns or {}).get(task)
            row = _learned_verdict(base, rule, frame_rows, min_seeds,
                                   functools.partial(random_return, task) if given is None
                                   else functools.partial(float, given))
            row.advantage = _advantage_rows(cell_results, published, task, str(method), str(variant), frames)
        row.statistic, row.band = statistic_text(row), band_text(row)
        rows.append(row)
    return rows


def _not_comparable(row: VerdictRow) -> VerdictRow:
    """``row`` made "not comparable" when its environment differs from the published curves' (a short cell stays
    "not enough data", the difference added to its note)."""
    if not row.environment:
        return row
    if row.verdict == NOT_ENOUGH:
        later = "a longer run with this environment is 'not comparable' (column Environment)"
        row.note = f"{row.note}; {later}" if row.note else later
        return row
    row.verdict = NOT_COMPARABLE
    row.note = (f"its environment differs from the published curves' ({row.environment}); the band is that of "
                f"{PUBLISHED_ENV_TEXT}")
    return row


def _first_published_frame(task: str) -> int:
    frames = published_frames(task, math.inf)
    return frames[0] if frames else 0


def statistic_text(row: VerdictRow) -> str:
    """The verdict table's Statistic: what the rule reads (the mean over the cell's seeds) at each frame it reads, or
    "n/a" with the reason."""
    if not row.frames:
        first = frames_text(_first_published_frame(row.task))
        return f"n/a: no published evaluation frame reached (the first is {first}; the runs reach " \
               f"{frames_text(row.reached)})"
    so_far = " (so far)" if row.verdict == NOT_ENOUGH else ""
    if row.method == BASELINE:
        values = "; ".join(f"{fmt_num(f.mean)} at {frames_text(f.frame)}" for f in row.frames)
        return f"mean of {row.seeds} seed(s): {values}{so_far}"
    last = row.frames[-1]
    return (f"mean of {row.seeds} seed(s): {fmt_num(last.mean)} at {frames_text(last.frame)} (seeds "
            f"{fmt_num(last.low)}-{fmt_num(last.high)}){so_far}")


def band_text(row: VerdictRow) -> str:
    """The verdict table's Band: DrQ-v2's published band at each frame read; another method's learned threshold; or
    "n/a" with the reason."""
    if row.method == BASELINE:
        if not row.frames:
            return "n/a: no published evaluation frame reached"
        return "; ".join(f"[{fmt_num(f.band_low)}, {fmt_num(f.band_high)}] at {frames_text(f.frame)}"
                         for f in row.frames)
    if math.isnan(row.threshold) and row.verdict == NOT_COMPARABLE:
        return "n/a: no threshold for an environment other than the published curves'"
    if math.isnan(row.threshold):
        rule = RULES.get(row.task)
        at = frames_text(rule.learned_frame) if rule else "the learned frame"
        return f"n/a: the threshold is set once every seed reaches {at} (the learned frame)"
    last = row.frames[-1]
    return (f">= {fmt_num(row.threshold)} at {frames_text(last.frame)} = random {fmt_num(row.random_return)} + "
            f"{LEARNED_SHARE:g} x (published DrQ-v2 {fmt_num(last.published_mean)} - random)")


def false_alarm_text(row: VerdictRow) -> str:
    """The verdict table's False alarm: the rate for the cell's seed count, or "n/a" with the reason."""
    if row.method != BASELINE:
        return ("n/a: the learned rule reads a threshold, not a band of published seeds (no TACO seeds are "
                "published to derive a rate from)")
    if not math.isnan(row.false_alarm):
        rate = 100 * row.false_alarm
        text = f"{rate:.0f}%" if rate == 0 or rate >= 1 else f"{rate:.1g}%"
        return f"{text} for {row.seeds} seed(s)" + (" (at the frames reached so far)" if row.verdict == NOT_ENOUGH
                                                    else "")
    if not row.frames:
        return "n/a: no published evaluation frame reached"
    published = min(f.published_n for f in row.frames)
    return (f"n/a: the rate needs {row.seeds} + 2 published seeds (one set judged against a band of at least two "
            f"others); {published} are published")


def _advantage_rows(cell: Results, published: Results, task: str, method: str, variant: str,
                    frames: Sequence[int]) -> list[AdvantageRow]:
    """At each published frame every seed reaches: P(a seed of the cell > a published DrQ-v2 seed) with its
    bootstrap interval (rliable's estimator and random state, :func:`analysis.stats.poi_interval`)."""
    out = []
    for f in frames:
        vals = values_at(cell, f)["value"].to_numpy(dtype=float)
        pub = values_at(published, f, task)["value"].to_numpy(dtype=float)
        if not len(vals) or not len(pub):
            continue
        poi, low, high = poi_interval(vals[:, None], pub[:, None])
        out.append(AdvantageRow(task, method, variant, int(f), len(vals), len(pub), poi, low, high))
    return out


def cell_health(root: str | Path, cell: pd.DataFrame) -> dict[str, object]:
    """``health``: "seed N: actor saturated since frame F: ..." for each run of ``cell`` whose actor is saturated at
    the end of its train.csv (the rule of repro/runs/health.py), and "seed N: actor at the bound since frame F: ..."
    for one at the bound for a shorter stretch so far; "" when none is; ``health_logged``: whether every run logs the
    metric."""
    out, logged = [], True
    for run_id, seed in zip(cell["run_id"], cell["seed"]):
        rows = read_rows(Path(root) / str(run_id))
        logged = logged and bool(rows)
        found = at_bound(rows)
        if found is not None:
            out.append(f"seed {seed}: {found.message()}")
    return {"health": "; ".join(out), "health_logged": logged}


def environment_differences(cfg: dict, task: str) -> list[str]:
    """How one run's config (``env``) differs from the environment of the published curves (the paper's DMC settings:
    analysis/comparable.py's one rule, worded against "published"): e.g. ["100-frame episodes (published: 1,000)"];
    [] when it does not."""
    env = cfg.get("env") or {} if isinstance(cfg, dict) else {}
    return env_difference({**env, "task": task, "suite": "dmc"}, against="published")


def cell_environment(root: str | Path, cell: pd.DataFrame, task: str) -> str:
    """How the environment of the runs of ``cell`` differs from the published curves': "" when none does; a run
    without a readable config.yaml is taken as configured by default."""
    found: list[str] = []
    for run_id in cell["run_id"]:
        path = Path(root) / str(run_id) / runformat.CONFIG
        try:
            cfg = read_config(path)
        except (OSError, ValueError):
            continue
        found += [d for d in environment_differences(cfg, task) if d not in found]
    return "; ".join(found)


def health_text(row: VerdictRow) -> str:
    """The verdict table's actor column: the seeds at the bound, else whether the seeds' actors were watched."""
    return row.health or ("not saturated" if row.health_logged else "not logged (a run written before issue 49)")


def _frame_rows(cell: Results, published: Results, task: str, method: str, variant: str,
                frames: Sequence[int]) -> list[FrameRow]:
    out = []
    for f in frames:
        vals = values_at(cell, f)["value"].to_numpy(dtype=float)
        pub = values_at(published, f, task)["value"].to_numpy(dtype=float)
        if not len(vals) or len(pub) < 2:
            continue
        lo, hi = band(pub)
        mean = float(vals.mean())
        out.append(FrameRow(task, method, variant, int(f), len(vals), mean, float(vals.min()), float(vals.max()),
                            len(pub), float(pub.mean()), float(pub.min()), float(pub.max()), lo, hi,
                            position(mean, lo, hi)))
    return out


def _short(base: dict, rule: TaskRule, need: int, min_seeds: int, what: str) -> str | None:
    """Why the cell is not enough data, or None."""
    if base["seeds"] < min_seeds:
        return f"{base['seeds']} seed(s); the check needs at least {min_seeds}"
    if not comparable.reached(base["reached"], need):
        return (f"every seed must reach {frames_text(need)} ({what}); they reach "
                f"{frames_text(base['reached'])}")
    return None


def _baseline_verdict(base: dict, rule: TaskRule, published: Results, frames: Sequence[int],
                      frame_rows: Sequence[FrameRow], min_seeds: int) -> VerdictRow:
    text = (f"mean over seeds inside the published band (seeds' range ± {BAND_SD:g} sd) at every published frame "
            "reached")
    why = _short(base, rule, rule.verdict_frame, min_seeds, "the verdict frame")
    judged = [int(f) for f in frames]
    rate = false_alarm_rate(published_matrix(base["task"], judged, published), base["seeds"]) if judged else math.nan
    if why is not None:
        return _not_comparable(VerdictRow(**base, verdict=NOT_ENOUGH, rule=text, false_alarm=rate, note=why))
    places = {r.position for r in frame_rows}
    verdict = BELOW if UNDER in places else ABOVE if OVER in places else LEARNS
    off = [f"{frames_text(r.frame)}: {fmt_num(r.mean)} vs band [{fmt_num(r.band_low)}, {fmt_num(r.band_high)}]"
           for r in frame_rows if r.position != INSIDE]
    return _not_comparable(VerdictRow(**base, verdict=verdict, rule=text, false_alarm=rate, note="; ".join(off)))


def _learned_verdict(base: dict, rule: TaskRule, frame_rows: Sequence[FrameRow], min_seeds: int,
                     random_of: Callable[[], float]) -> VerdictRow:
    """``random_of``: the task's random-policy return, simulated only when a verdict needs it."""
    text = (f"mean over seeds at the last published frame reached >= random + {LEARNED_SHARE:g} x (published DrQ-v2 "
            "mean - random)")
    why = _short(base, rule, rule.learned_frame, min_seeds, "the learned frame")
    if why is not None or not frame_rows:
        return _not_comparable(VerdictRow(**base, verdict=NOT_ENOUGH, rule=text,
                                          note=why or "no published frame reached"))
    if base["environment"]:  # no verdict: the threshold (and its random-policy reference) is not simulated
        return _not_comparable(VerdictRow(**base, verdict=NOT_COMPARABLE, rule=text))
    rand = random_of()
    last = frame_rows[-1]
    threshold = rand + LEARNED_SHARE * (last.published_mean - rand)
    verdict = LEARNED if last.mean >= threshold else NOT_LEARNED
    note = "" if verdict == LEARNED else f"{fmt_num(threshold - last.mean)} under the threshold"
    return VerdictRow(**base, verdict=verdict, rule=text, threshold=threshold, random_return=rand, note=note)


# ---------------------------------------------------------------------------------------------------- tables
VERDICT_COLUMNS = ["task", "method", "variant", "seeds", "reached", "environment", "verdict", "statistic", "band",
                   "false_alarm", "threshold", "random_return", "rule", "note", "health", "health_logged"]
FRAME_COLUMNS = list(FrameRow.__dataclass_fields__)
ADVANTAGE_COLUMNS = list(AdvantageRow.__dataclass_fields__)
ADVANTAGE_NOTE = ("An observation at a small budget, never a verdict on the paper's claims (those are judged by "
                  "`repro claims` at their own budgets and seeds): P(X > Y) is the probability that one seed of the "
                  "method beats one published DrQ-v2 seed at that frame (rliable's probability of improvement, ties "
                  "counting a half); the interval is its 95% stratified-bootstrap interval over both sets of seeds "
                  "(rliable's, random state fixed). With one seed of the method it is the share of published seeds "
                  "that seed beats.")


def verdict_frame(rows: Sequence[VerdictRow]) -> pd.DataFrame:
    return pd.DataFrame([{k: getattr(r, k) for k in VERDICT_COLUMNS} for r in rows], columns=VERDICT_COLUMNS)


def frames_frame(rows: Sequence[VerdictRow]) -> pd.DataFrame:
    return pd.DataFrame([fr.__dict__ for r in rows for fr in r.frames], columns=FRAME_COLUMNS)


def advantage_frame(rows: Sequence[VerdictRow]) -> pd.DataFrame:
    return pd.DataFrame([a.__dict__ for r in rows for a in r.advantage], columns=ADVANTAGE_COLUMNS)


def advantage_display(rows: Sequence[VerdictRow]) -> pd.DataFrame:
    """The advantage table as read (verify_advantage.md, the report): frames with their unit, the interval beside
    the value."""
    adv = advantage_frame(rows)
    return pd.DataFrame({
        "Task": adv["task"], "Method": adv["method"], "Variant": adv["variant"],
        "Environment frames (action repeat 2)": [frames_text(f) for f in adv["frame"]],
        "Seeds (method / published)": [f"{n} / {p}" for n, p in zip(adv["n"], adv["published_n"])],
        "P(X > Y) [95% CI]": [f"{v:.2f} [{lo:.2f}, {hi:.2f}]" for v, lo, hi in
                              zip(adv["poi"], adv["poi_low"], adv["poi_high"])]})


def advantage_lines(rows: Sequence[VerdictRow]) -> list[str]:
    """One line per method other than DrQ-v2: its P(X > Y) against the published seeds at each judged frame."""
    out = []
    for r in rows:
        if r.advantage:
            cells = ", ".join(f"{frames_text(a.frame)} {a.poi:.2f} [{a.poi_low:.2f}, {a.poi_high:.2f}]"
                              for a in r.advantage)
            out.append(f"{r.task} {r.method} ({r.variant}, {r.seeds} seed(s)) vs the published DrQ-v2 seeds, "
                       f"P(X > Y) [95% CI]: {cells} (an observation at a small budget, not a verdict)")
    return out


def _ranges(rule: TaskRule) -> str:
    """The published seeds' range at each published frame up to the verdict frame."""
    frames = published_frames(rule.task, rule.verdict_frame)
    pub = published_matrix(rule.task, frames)
    return ", ".join(f"{fmt_num(pub[:, j].min())}-{fmt_num(pub[:, j].max())} at {frames_text(f)}"
                     for j, f in enumerate(frames))


FRAMES_NOTE = ("Frames are environment frames = agent steps x action repeat (the published curves' repeat: 2; a run of "
               "another repeat is not comparable, as its Position says).")


def verdict_notes() -> list[str]:
    rules = " ".join(f"{r.task}: DrQ-v2 judged once every seed reaches {frames_text(r.verdict_frame)}, TACO "
                     f"from {frames_text(r.learned_frame)} (published seeds: {_ranges(r)})." for r in RULES.values())
    return [
        f"Published: {SOURCE_TEXT}.",
        f"DrQ-v2: at every published evaluation frame after 0 that every seed reaches, the mean over seeds must lie in "
        f"the published band: the published seeds' range widened by {BAND_SD:g} standard deviation of those seeds at "
        "that frame. False alarm: the share of sets of as many published seeds (a correct pipeline) that the same "
        "rule, with the band of the other published seeds, calls outside the band at the same frames.",
        f"Other methods (TACO): 'learned' when the mean over seeds at the last published frame they all reach is at "
        f"least the random policy's return plus {LEARNED_SHARE:g} of the way to the published DrQ-v2 mean there. "
        f"Random policy: uniform actions, {RANDOM_EPISODES} episodes, action repeat 2.",
        "'not enough data' (never a verdict) when a seed has not reached the frame the verdict needs (its last "
        "evaluation is before it). Frames are environment frames = agent steps x action repeat (the runs' repeat "
        "beside the frames reached; the published curves': 2). " + rules,
        f"'not comparable' (never a verdict) when the runs' environment differs from {PUBLISHED_ENV_TEXT} (column "
        "Environment): their returns are not on the published curves' scale (a 100-frame episode returns about a "
        "tenth of a 1000-frame one).",
    ]


def environment_display(row: VerdictRow) -> str:
    """The Environment column: the difference from the published curves' settings, or that there is none."""
    return f"{row.environment}: not comparable" if row.environment else "as published"


def verdict_display(rows: Sequence[VerdictRow]) -> pd.DataFrame:
    """The verdict table as verify.md and the report show it: the statistic, the band and the false-alarm rate in
    columns of their own (never an empty cell where there is a number; "n/a" with the reason where there is none)."""
    return pd.DataFrame({
        "Task": [r.task for r in rows], "Method": [r.method for r in rows], "Variant": [r.variant for r in rows],
        "Seeds": [r.seeds for r in rows],
        "Env. frames reached": [frames_text(r.reached) + comparable.repeat_text(r.repeats) for r in rows],
        "Environment": [environment_display(r) for r in rows], "Verdict": [r.verdict for r in rows],
        "Statistic": [r.statistic for r in rows], "Band (DrQ-v2) / threshold (others)": [r.band for r in rows],
        "False alarm": [false_alarm_text(r) for r in rows], "Note": [r.note for r in rows],
        "Actor": [health_text(r) for r in rows]},
        columns=["Task", "Method", "Variant", "Seeds", "Env. frames reached", "Environment", "Verdict", "Statistic",
                 "Band (DrQ-v2) / threshold (others)", "False alarm", "Note", "Actor"])


VERDICT_ORDER = (LEARNS, BELOW, ABOVE, LEARNED, NOT_LEARNED, NOT_ENOUGH, NOT_COMPARABLE)


def verdict_caption(rows: Sequence[VerdictRow]) -> str:
    """verify.md's caption: the verdicts counted (they add up to the table's rows)."""
    counts = {v: sum(r.verdict == v for r in rows) for v in VERDICT_ORDER}
    return ("repro verify: the verify runs against the DrQ-v2 authors' published curves (" +
            (", ".join(f"{n} {v}" for v, n in counts.items() if n) or "no verify runs") + ").")


def write_verdicts(out_dir: Path, rows: Sequence[VerdictRow]) -> tuple[TableOutput, TableOutput]:
    """``verify.csv/.md/.tex`` (one verdict per cell) and ``verify_frames.csv/.md/.tex`` (each judged frame)."""
    verdicts = write_table(out_dir, "verify", verdict_frame(rows), verdict_caption(rows), verdict_display(rows),
                           verdict_notes())
    fr = frames_frame(rows)
    envs = {(r.task, r.method, r.variant): r.environment for r in rows}
    fr_display = pd.DataFrame({
        "Task": fr["task"], "Method": fr["method"], "Variant": fr["variant"],
        "Env. frames": [frames_text(f) for f in fr["frame"]],
        "Runs: mean (seeds' range)": [f"{fmt_num(m)} ({fmt_num(lo)}-{fmt_num(hi)}, n={n})"
                                      for m, lo, hi, n in zip(fr["mean"], fr["low"], fr["high"], fr["n"])],
        "Published: mean (range)": [f"{fmt_num(m)} ({fmt_num(lo)}-{fmt_num(hi)}, n={n})" for m, lo, hi, n in
                                    zip(fr["published_mean"], fr["published_min"], fr["published_max"],
                                        fr["published_n"])],
        "Band": [f"[{fmt_num(lo)}, {fmt_num(hi)}]" for lo, hi in zip(fr["band_low"], fr["band_high"])],
        "Position": [p + (f" (not comparable: {envs[(t, m, v)]})" if envs.get((t, m, v)) else "")
                     for p, t, m, v in zip(fr["position"], fr["task"], fr["method"], fr["variant"])]})
    frames_table = write_table(out_dir, "verify_frames", fr, "repro verify: each judged frame against the published "
                               f"band (the seeds' range ± {BAND_SD:g} sd).", fr_display,
                               [*verdict_notes()[:2], FRAMES_NOTE])
    adv, adv_display = advantage_frame(rows), advantage_display(rows)
    write_table(out_dir, "verify_advantage", adv, "repro verify: each method other than DrQ-v2 against the DrQ-v2 "
                "authors' published seeds at every judged frame, probability of improvement.", adv_display,
                [ADVANTAGE_NOTE, f"Published: {SOURCE_TEXT}."])
    return verdicts, frames_table


KEPT_FILES = (runformat.CONFIG, runformat.RESOLVED, runformat.META, runformat.EVAL, runformat.TRAIN, runformat.DONE)


def keep_runs(results: Results, out_dir: Path, cells: pd.DataFrame | None = None) -> list[Path]:
    """Copy the small files of every verify run (config, resolved values, provenance, evaluations, training
    episodes, DONE; no checkpoint, no replay) to ``out_dir/runs/<run>/``: a run directory `repro verify
    --judge-only --results out_dir/runs` judges again, kept beside the verdicts (docs/verification/). ``cells``: the
    runs judged (:attr:`Judgement.cells`; by default :func:`verify_cells` of ``results``)."""
    cells = verify_cells(results) if cells is None else cells
    written = []
    for run_id in cells["run_id"] if not cells.empty else []:
        for name in KEPT_FILES:
            src = Path(results.root) / str(run_id) / name
            if src.is_file():
                written.append(atomic_write_text(out_dir / "runs" / str(run_id) / name, src.read_text()))
    return written


def verdict_lines(rows: Sequence[VerdictRow]) -> list[str]:
    """One line per cell for the terminal."""
    out = []
    for r in rows:
        env = f", {r.environment}" if r.environment else ""
        out.append(f"{r.task} {r.method} ({r.variant}, {r.seeds} seed(s), {frames_text(r.reached)}{env}): "
                   f"{r.verdict} — statistic {r.statistic}; {'band' if r.method == BASELINE else 'threshold'} "
                   f"{r.band}; false alarm {false_alarm_text(r)}" + (f" — {r.note}" if r.note else "")
                   + (f" — {r.health}" if r.health else ""))
    return out
