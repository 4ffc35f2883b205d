"""Shared inputs of every artifact and claim: loaded runs, frame budget, bootstrap settings, paper data."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import pandas as pd

from analysis.cache import lookup
from analysis.comparable import FRAMES, Budget
from analysis.load import Results
from analysis.paper import PaperData
from analysis.scores import DEFAULT_BUDGET, final_scores, learning_curves
from analysis.stats import DEFAULT_REPS, DEFAULT_SEED

CURVE_REPS = 2_000  # bootstrap repetitions for per-frame learning-curve bands (one CI per grid point)


@dataclass
class Context:
    """Settings and cached derived tables shared by artifacts, claims and the report.

    Attributes:
        results: the loaded results root.
        budget: frame budget of "score at N frames" (the paper's 1M).
        reps: bootstrap repetitions of table CIs and rliable aggregates (rliable's default 50,000).
        curve_reps: repetitions of the per-frame CI bands of learning curves.
        seed: the bootstrap random state.
        experiment_map: canonical experiment -> actual experiment names (see analysis.select).
        out_dir: where artifacts are written.
        tsne_n: noisy copies per centroid in F6 (the paper's 1000).
        tsne_iter: t-SNE iterations (scikit-learn's default 1000).
        render_envs: whether F13 may build environments to render frames.
        min_seeds: seeds per cell a claim needs before it gets a verdict (each claim also has its own
            minimum in analysis/claim_budgets.csv; the larger applies).
        indicative: also give a labelled indicative reading of each claim whose runs fall short of its
            budget or seed count (never a supported/refuted verdict).
        below_budget: set by analysis.claims on the context of an indicative reading: cells use the
            runs' latest scores instead of needing to have reached the claim's budget.
        budget_label: what a run must reach, in words, where ``budget`` is not a frame count (offline
            claims: "its configured offline.updates").
        published_band: draw the DrQ-v2 authors' published curve (mean and 95% CI band) beside the runs on
            the learning-curve figures that have it (F4).
        cache: results shared between artifacts and claims (e.g. the t-SNE of F6).
    """

    results: Results
    paper: PaperData = field(default_factory=PaperData)
    budget: int = DEFAULT_BUDGET
    reps: int = DEFAULT_REPS
    curve_reps: int = CURVE_REPS
    seed: int = DEFAULT_SEED
    experiment_map: dict[str, list[str]] = field(default_factory=dict)
    out_dir: Path = Path("results/report")
    tsne_n: int = 1000
    tsne_iter: int = 1000
    render_envs: bool = True
    min_seeds: int = 2
    indicative: bool = False
    below_budget: bool = False
    budget_label: str | None = None
    published_band: bool = True
    cache: dict = field(default_factory=dict)

    @property
    def published(self) -> Results:
        """The DrQ-v2 authors' published curves (analysis.load.load_published), a Results of their own: never
        merged into ``results``."""
        from analysis.calibration import packaged_published

        return packaged_published()

    @cached_property
    def scores(self) -> pd.DataFrame:
        """Per-run score at the budget (see analysis.scores.final_scores)."""
        return final_scores(self.results, self.budget)

    @property
    def curves(self) -> pd.DataFrame:
        """Every run's learning curve on a common frame grid (budget-independent: kept in ``cache``, which
        the per-claim contexts of analysis.claims share)."""
        if "curves" not in self.cache:
            # reused across commands while the evaluations are the same (analysis/cache.py)
            ev = self.results.eval
            key = hashlib.sha1(pd.util.hash_pandas_object(ev, index=False).to_numpy().tobytes()
                               + repr(list(ev.columns)).encode()).hexdigest()
            self.cache["curves"] = lookup("curves", key, lambda: learning_curves(self.results), process=False)
        return self.cache["curves"]

    @property
    def no_runs(self) -> bool:
        return self.results.empty

    def frames_budget(self, rows: pd.DataFrame | None = None) -> Budget:
        """``budget`` as environment frames, with the action repeats of ``rows`` (runs or scores) beside it."""
        repeats = () if rows is None or rows.empty or "action_repeat" not in rows.columns else tuple(
            sorted({int(r) for r in rows["action_repeat"].dropna()}))
        return Budget(self.budget, FRAMES, repeats)

    def budget_text(self) -> str:
        if self.budget_label is not None:
            return self.budget_label
        b = self.budget
        return f"{b / 1e6:g}M frames" if b >= 1_000_000 else f"{b:,} frames"
