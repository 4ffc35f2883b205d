"""The report's model: every section's rows that `repro report` shows beside the paper's tables and figures, built
once from the Context by :func:`build_model`.

The report's data flows one way: ``Context -> build_model (here) -> paper_figures draws (the artifacts, and the verify
figure from :attr:`ReportModel.verify`) -> repro_app/report.py writes (the sections' files, REPORT.md/.html)``. No
section is built twice in one report and nothing downstream calls back into analysis for rows the model holds
(tests/test_report_model.py counts the builders' calls during one report).
"""

from __future__ import annotations

from dataclasses import dataclass

from analysis.audit import Finding, run_audit
from analysis.calibration import CalibrationRow, calibrate
from analysis.claims import Verdict, claim_specs, evaluate_claims
from analysis.context import Context
from analysis.power import PowerRow, power_rows
from analysis.verify import Judgement, judgement

__all__ = ["ReportModel", "build_model"]


@dataclass(frozen=True, eq=False)
class ReportModel:
    """Each section of a report, built once.

    Attributes:
        verdicts: one per claim of ``claim_specs`` (claims.csv's order; analysis/claims).
        findings: the audit of the paper's own numbers (analysis/audit.py).
        calibration: the user's DrQ-v2 runs against the published curves, one row per cell (analysis/calibration.py).
        calibration_notes: the notes :func:`analysis.calibration.calibrate` gives with its rows.
        verify: `repro verify`'s verdicts and the runs they judged (the verify figure draws these).
        power: the claims' statistical power (analysis/power.py), conditioned on the runs when there are any.
        sims: the power simulation's draws.
        max_seeds: the most seeds per cell the power search tries.
        conditioned: whether ``power`` is conditioned on the runs (there are runs).
    """

    verdicts: tuple[Verdict, ...]
    findings: tuple[Finding, ...]
    calibration: tuple[CalibrationRow, ...]
    calibration_notes: tuple[str, ...]
    verify: Judgement
    power: tuple[PowerRow, ...]
    sims: int
    max_seeds: int
    conditioned: bool


def build_model(ctx: Context, sims: int, max_seeds: int) -> ReportModel:
    """Every section of the report from ``ctx``, each built once: the claims' verdicts, the audit, the calibration,
    `repro verify`'s verdicts and the claims' power (given those verdicts; the claims whose rule bootstraps in every
    draw are left to `repro plan --claims`), with ``sims`` draws and at most ``max_seeds`` seeds per cell. The claims
    are listed once (``claim_specs``) for the verdicts and the power, and the power reads the audit's findings."""
    specs = claim_specs(ctx.paper)
    verdicts = evaluate_claims(ctx, specs)
    findings = run_audit(ctx.paper)
    cal_rows, cal_notes = calibrate(ctx.results, ctx.published, ctx.reps, ctx.seed)
    verify = judgement(ctx.results)
    conditioned = not ctx.no_runs
    power = power_rows(ctx, sims, max_seeds, verdicts, conditioned, bootstrap_claims=False, findings=findings,
                       specs=specs)
    return ReportModel(tuple(verdicts), tuple(findings), tuple(cal_rows), tuple(cal_notes), verify, tuple(power),
                       sims, max_seeds, conditioned)
