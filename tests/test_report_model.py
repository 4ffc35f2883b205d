"""The report's data flows one way (docs/analysis.md, "Report"): analysis builds each section's rows once into the
report model (analysis/report_model.py), paper_figures draws from it, repro_app writes it. Counted here: every builder
of a section is entered once during one `build_report` (the claims listed once), the power reads no cells of the runs
that the claims read, and the verify figure draws the cells and verdicts the model holds without calling
analysis/verify.py again."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import analysis.audit
import analysis.calibration
import analysis.cells
import analysis.claims
import analysis.claims.draws
import analysis.power
import analysis.verify as V
import paper_figures.verify_plot
import repro_app.report
from analysis.context import Context
from analysis.load import load_results
from analysis.paper import DMC9
from analysis.report_model import build_model
from analysis_fixtures import write_run
from paper_figures.verify_plot import plot_verify
from repro_app.report import build_report

TASK = "cartpole_balance"
RANDOM = 300.0  # the random policy's return on TASK (instead of rolling it out)
PACKAGES = ("analysis", "paper_figures", "repro_app")


def count_calls(mp: pytest.MonkeyPatch, fn: Callable[..., Any], calls: list[str],
                replace: Callable[..., Any] | None = None) -> None:
    """Record each call of ``fn`` in ``calls`` (its name), wherever it is called from: every loaded module of the
    project that holds ``fn`` under a name (its own, and each module that imported it by name) gets a wrapper.
    ``replace``: call this instead of ``fn``."""
    target = replace or fn

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        calls.append(fn.__name__)
        return target(*args, **kwargs)

    found = 0
    for name, module in list(sys.modules.items()):
        if module is None or not name.startswith(PACKAGES):
            continue
        for attr, value in list(vars(module).items()):
            if value is fn:
                mp.setattr(module, attr, wrapper)
                found += 1
    assert found, f"{fn.__name__} is in no loaded module"


def verify_runs(root: Path) -> Path:
    """Two verify cells on TASK (DrQ-v2 and TACO, one seed each) under ``root``."""
    for agent, curve in (("drqv2", [350, 300, 800, 980]), ("taco", [350, 900, 990, 990])):
        write_run(root, experiment="verify", agent=agent, task=TASK, seed=1, final=0.0, frames=60_000,
                  eval_every=20_000, curve=curve, batch_size=256)
    return root


# Each section's builder: its rows are built by this one call in a report (analysis/report_model.py).
BUILDERS: dict[str, Callable[..., Any]] = {
    "claims": analysis.claims.evaluate_claims,
    "audit": analysis.audit.run_audit,
    "calibration": analysis.calibration.calibrate,
    "verify": V.judgement,
    "verify cells": V.verify_cells,
    "power": analysis.power.power_rows,
    "verify figure": plot_verify,
    "claim list": analysis.claims.claim_specs,  # not a section: the claims, listed once for the verdicts and power
}


@pytest.fixture(scope="module")
def report_calls(tmp_path_factory) -> tuple[list[str], Path]:
    """The builders' calls during one `build_report` of a small tree (two verify cells), and its folder."""
    root = verify_runs(tmp_path_factory.mktemp("results"))
    ctx = Context(results=load_results(root), out_dir=root / "out", budget=60_000, reps=100, curve_reps=50,
                  tsne_n=30, tsne_iter=250, render_envs=False)
    calls: list[str] = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(repro_app.report, "REPORT_SIMS", 20)  # the power section's draws: counted here, not read
        mp.setattr(V, "random_return", lambda task, episodes=V.RANDOM_EPISODES: RANDOM)
        for fn in BUILDERS.values():
            count_calls(mp, fn, calls)
        build_report(ctx)
    return calls, ctx.out_dir


@pytest.mark.parametrize("section", list(BUILDERS))
def test_each_section_is_built_once_in_a_report(report_calls, section):
    calls, out = report_calls
    assert calls.count(BUILDERS[section].__name__) == 1, calls
    assert (out / "REPORT.md").is_file() and (out / "verify.png").is_file()


def test_the_report_shows_what_the_model_holds(report_calls):
    _, out = report_calls
    md = (out / "REPORT.md").read_text()
    assert "## repro verify:" in md and "![verify](verify.png)" in md
    assert "learns as published" in (out / "verify.md").read_text()
    for name in ("claims", "audit", "calibration", "plan_power", "plan_power_cells", "verify", "verify_frames"):
        assert (out / f"{name}.csv").is_file(), name


def test_verify_plot_draws_the_cells_and_verdicts_of_the_model(tmp_path, monkeypatch):
    """The figure draws the runs and verdicts it is given: a model holding only the DrQ-v2 cell draws that cell
    alone although the results hold TACO's too, and nothing of analysis/verify.py that judges or picks runs is
    called."""
    results = load_results(verify_runs(tmp_path))
    full = V.judgement(results, random_returns={TASK: RANDOM})
    assert {r.method for r in full.rows} == {"DrQ-v2", "TACO"}
    keep = full.cells["method"] == "DrQ-v2"
    model = V.Judgement(tuple(r for r in full.rows if r.method == "DrQ-v2"), full.cells[keep])

    def judged_again(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("verify_plot asked analysis.verify for rows the model holds")

    for fn in (V.judgement, V.judge, V.verify_cells):
        count_calls(monkeypatch, fn, [], replace=judged_again)
    drawn: list[tuple[list[str], tuple]] = []
    draw_panel = paper_figures.verify_plot.draw_panel

    def recorded(ax, res, cell, task, rows):
        drawn.append((list(cell["run_id"]), tuple(rows)))
        return draw_panel(ax, res, cell, task, rows)

    monkeypatch.setattr(paper_figures.verify_plot, "draw_panel", recorded)
    paths = plot_verify(results, model, tmp_path / "out")
    assert [p.suffix for p in paths] == [".png", ".pdf"] and all(p.stat().st_size > 5000 for p in paths)
    assert drawn == [(list(full.cells.loc[keep, "run_id"]), model.rows)]


def test_the_power_reuses_the_cells_of_the_runs_the_claims_read(tmp_path, monkeypatch):
    """The power conditioned on the runs reads no claim's cells that evaluate_claims read: each (cells, claim
    context) is read from the runs once in a report model (analysis.claims.claim_cells), the online claims' cells by
    their checks (the main runs reach 1M frames), and the power reads them through the same cache."""
    for agent, final in (("taco", 600.0), ("drqv2", 400.0)):
        for seed in (1, 2, 3):
            write_run(tmp_path, experiment="main", agent=agent, task=DMC9[0], seed=seed, final=final,
                      frames=1_000_000, eval_every=500_000)
    ctx = Context(results=load_results(tmp_path), out_dir=tmp_path / "out", reps=50)
    reads: list[tuple[str, Any, int]] = []  # (the builder running, the cells function, id of the claim context)
    running = ["none"]
    read_cells = analysis.claims.draws.read_cells

    def recorded_read(cctx: Context, cells: Callable[..., Any]) -> Any:
        reads.append((running[0], cells, id(cctx)))
        return read_cells(cctx, cells)

    def running_in(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            running[0] = name
            try:
                return fn(*args, **kwargs)
            finally:
                running[0] = "none"
        return wrapper

    count_calls(monkeypatch, read_cells, [], replace=recorded_read)
    observed = analysis.cells.observed_cells  # each claim's cells function calls it once
    looked: list[str] = []  # the builder running at each call

    def recorded_look(*args: Any, **kwargs: Any) -> Any:
        looked.append(running[0])
        return observed(*args, **kwargs)

    count_calls(monkeypatch, observed, [], replace=recorded_look)
    count_calls(monkeypatch, analysis.claims.evaluate_claims, [],
                replace=running_in("claims", analysis.claims.evaluate_claims))
    count_calls(monkeypatch, analysis.power.power_rows, [], replace=running_in("power", analysis.power.power_rows))
    model = build_model(ctx, sims=20, max_seeds=4)
    assert model.conditioned and {r.id for r in model.power if r.now is not None} >= {
        "online_avg_gain", "online_beats_drqv2_all", "online_beats_model_based"}
    read = [(fn, c) for _, fn, c in reads]
    assert len(read) == len(set(read)), reads  # no cells read twice
    by_claims = {(fn, c) for who, fn, c in reads if who == "claims"}
    online = {(fn, c) for fn, c in by_claims if fn.__name__ == "_online_cells"}
    assert len(online) == 1, reads  # the online claims' checks read the main runs' cells, at 1M frames
    # ... which the power of the four online claims (avg gain and its published reading, beats DrQ-v2, beats
    # model-based) reuses without reading them again
    assert not any(fn.__name__ == "_online_cells" for who, fn, _ in reads if who == "power"), reads
    # and the power reads the runs only through the claims' cells (no read that bypasses them)
    assert looked.count("power") == sum(who == "power" for who, _, _ in reads), (looked, reads)
    kept = [value[1] for key, value in ctx.cache.items()
            if isinstance(key, tuple) and key[0] == "claim-cells" and key[1].__name__ == "_online_cells"]
    assert [sorted(len(v) for v in c.values()) for c in kept] == [[3, 3]]  # TACO and DrQ-v2, 3 seeds each
