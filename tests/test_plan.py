"""`repro plan`: the claims' power by simulation through their own rules (analysis/power.py) and the sweeps' cost
from a bench file (repro/launch/cost.py, its tables repro_app/plan.py)."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm
from typer.testing import CliRunner

# imported here, not first inside CliRunner: submitit binds a log handler to the stderr of its import
import repro.launch.slurm  # noqa: F401, I001
from analysis import claims as cl
from analysis import power
from analysis.cells import CellSource
from analysis.claim_budget import ClaimBudget
from analysis.context import Context
from analysis.load import Results
from helpers import bench_app
from repro.launch.cost import RunBudget, find_bench, frames_to_train, makespan, plan_sweeps, totals
from repro_app.cli import app

SPEC = ClaimBudget("toy", "frames", 1_000_000, 1, 6, ("main",), "", "", "test")


@pytest.fixture(scope="module")
def ctx() -> Context:
    return Context(results=Results(Path("."), pd.DataFrame(), pd.DataFrame()))


def _pairs_claim(effects: list[tuple[float, float, float, float]]) -> power.SimClaim:
    """A claim 'A > B on every pair' (analysis.claims.universal) over independent normal cells."""
    cells = []
    for i, (ma, sa, mb, sb) in enumerate(effects):
        cells += [CellSource((f"t{i}", "A"), "normal", ma, sa),
                  CellSource((f"t{i}", "B"), "normal", mb, sb)]
    pairs = [((f"t{i}", "A"), (f"t{i}", "B"), f"t{i}") for i in range(len(effects))]
    return power.SimClaim("toy", SPEC, cells, lambda c, draws: cl.universal(draws, pairs, c.min_seeds, c.budget_text()))


def _analytic(ma: float, sa: float, mb: float, sb: float, n: int) -> float:
    """P(mean of n draws of A > mean of n draws of B) for two normal cells."""
    return float(norm.cdf((ma - mb) / math.sqrt((sa**2 + sb**2) / n)))


def test_one_cell_rule_matches_the_analytic_two_sample_power(ctx):
    effect = (234.0, 21.0, 206.0, 32.0)  # Table 1's reach_duplo, without truncation
    for n in (3, 6):
        p = power.simulate(ctx, _pairs_claim([effect]), n, sims=4000, seed=1)
        assert abs(p.supported - _analytic(*effect, n)) < 3 * p.error + 1e-9, (n, p)
        assert p.supported + p.refuted == pytest.approx(1.0)


def test_a_rule_over_independent_cells_is_about_the_product_of_their_powers(ctx):
    effects = [(261.0, 52.0, 189.0, 35.0), (234.0, 21.0, 206.0, 32.0), (541.0, 38.0, 520.0, 40.0)]
    p = power.simulate(ctx, _pairs_claim(effects), 6, sims=4000, seed=2)
    expected = float(np.prod([_analytic(*e, 6) for e in effects]))
    assert abs(p.supported - expected) < 3 * p.error, (p, expected)


def test_simulation_is_deterministic_under_a_fixed_random_state(ctx):
    claim = _pairs_claim([(10.0, 5.0, 9.0, 5.0)])
    a, b = power.simulate(ctx, claim, 4, 500, seed=7), power.simulate(ctx, claim, 4, 500, seed=7)
    assert a == b
    assert power.seeds_for(ctx, claim, sims=300, seed=7, max_seeds=40) == \
        power.seeds_for(ctx, claim, sims=300, seed=7, max_seeds=40)


def test_a_claims_powers_are_kept_by_their_arguments(ctx):
    """simulate() keeps each result in the claim's memo: asked again with the same arguments it gives the same
    Power, and with other seeds, draws, random state or seeds done it computes (what a fresh claim gives)."""
    effect = [(10.0, 5.0, 8.0, 5.0)]
    claim = _pairs_claim(effect)
    done = {("t0", "A"): np.array([1.0, 2.0, 3.0]), ("t0", "B"): np.array([5.0, 6.0, 7.0])}
    calls = [(4, 300, 7, None), (5, 300, 7, None), (4, 200, 7, None), (4, 300, 8, None), (4, 300, 7, done)]
    first = [power.simulate(ctx, claim, n, sims, seed=s, observed=o) for n, sims, s, o in calls]
    assert len(claim.memo) == len(calls)
    assert [power.simulate(ctx, claim, n, sims, seed=s, observed=o) for n, sims, s, o in calls] == first
    assert len(claim.memo) == len(calls)
    assert first == [power.simulate(ctx, _pairs_claim(effect), n, sims, seed=s, observed=o)
                     for n, sims, s, o in calls]
    assert first[0] != first[4]


def test_seeds_for_80_percent_power_and_the_seed_minimum(ctx):
    claim = _pairs_claim([(10.0, 5.0, 8.0, 5.0)])
    n, p = power.seeds_for(ctx, claim, sims=2000, seed=3, max_seeds=40)
    assert n is not None and p.supported >= power.TARGET
    exact = next(k for k in range(1, 100) if _analytic(10.0, 5.0, 8.0, 5.0, k) >= power.TARGET)  # 9
    assert abs(n - exact) <= 1  # the simulated power at exact - 1 is within the Monte-Carlo error of 0.8
    # below the claim's seed minimum a cell is missing: 'not enough data', never supported
    strict = power.SimClaim("toy", ClaimBudget("toy", "frames", 1, 5, 6, (), "", "", ""), claim.cells, claim.judge)
    assert power.simulate(ctx, strict, 3, 200, seed=0).supported == 0.0


def test_observed_seeds_are_kept_and_only_the_missing_ones_drawn(ctx):
    claim = _pairs_claim([(10.0, 5.0, 8.0, 5.0)])
    done = {("t0", "A"): np.array([1.0, 2.0, 3.0]), ("t0", "B"): np.array([5.0, 6.0, 7.0])}
    assert power.simulate(ctx, claim, 3, 200, seed=0, observed=done).refuted == 1.0  # nothing left to draw
    more = power.simulate(ctx, claim, 40, 400, seed=0, observed=done)
    assert 0.0 < more.supported < 1.0


def test_a_normal_cells_draws_are_scipys_truncnorm_draws_bit_for_bit():
    """CellSource.draw computes the truncation's constants once (analysis.cells._truncnorm_rvs): the same values
    as scipy.stats.truncnorm.rvs from the same random state, in the left- and right-tail branches, a bound at
    infinity, a mean outside the range and no bounds at all."""
    from scipy.stats import truncnorm

    cases = [(420.0, 80.0, 0.0, 1000.0), (995.0, 40.0, 0.0, 1000.0), (5.0, 30.0, 0.0, math.inf),
             (0.0, 1.0, 0.0, math.inf), (-50.0, 10.0, 0.0, math.inf), (1500.0, 100.0, 0.0, 1000.0),
             (3.0, 2.0, -math.inf, math.inf), (550.0, 300.0, 500.0, 600.0)]
    for i, (mean, std, low, high) in enumerate(cases):
        for sims, n in ((2000, 3), (7, 50), (1, 1)):
            drawn = CellSource(("t", "m"), "normal", mean, std, low, high).draw(np.random.default_rng(i), sims, n)
            a, b = (low - mean) / std, (high - mean) / std
            scipy_draws = truncnorm.rvs(a, b, loc=mean, scale=std, size=(sims, n),
                                        random_state=np.random.default_rng(i))
            assert drawn.shape == (sims, n) and np.array_equal(drawn, scipy_draws), (mean, std, low, high, sims, n)


def test_every_claim_is_simulated_or_says_why_not(ctx):
    simulated = {c.id for c in power.simulated_claims(ctx)}
    assert simulated == {s.id for s in cl.claim_specs(ctx.paper) if s.simulation is not None}
    assert all(s.not_simulated for s in cl.SPECS if s.id not in simulated)
    claim = next(c for c in power.simulated_claims(ctx) if c.id == "online_beats_drqv2_all")
    assert any(c.kind == "published" for c in claim.cells)  # the DrQ-v2 authors' per-seed values
    p = power.simulate(ctx, claim, 6, 200, seed=0)
    assert 0.0 <= p.supported <= 1.0 and p.sims == 200


def test_the_power_reads_the_audit_findings_and_the_claim_list_it_is_given(ctx, monkeypatch):
    """The report hands power_rows its audit's findings and its list of claims (analysis/report_model.py): a claim
    bounded by an audit check names the finding given (none when that finding matches), and the rows follow the list
    given, without running the audit or listing the claims again."""
    import analysis.audit

    findings = analysis.audit.run_audit(ctx.paper)
    listed = cl.claim_specs(ctx.paper)

    def again(*args, **kwargs):
        raise AssertionError("power_rows ran the audit or listed the claims again")

    monkeypatch.setattr(analysis.audit, "run_audit", again)
    monkeypatch.setattr(cl, "claim_specs", again)
    check = "online_gain_vs_published"
    (found,) = [f for f in findings if f.check == check]
    off = [f if f.check != check else dataclasses.replace(f, recomputed="9.876x") for f in findings]
    fine = [f if f.check != check else dataclasses.replace(f, match=True) for f in findings]
    published = [s for s in listed if s.id == cl.PUBLISHED_GAIN_ID]
    rows = power.power_rows(ctx, 20, 4, bootstrap_claims=False, findings=off, specs=published)
    assert [r.id for r in rows] == [cl.PUBLISHED_GAIN_ID] and not found.match
    assert "9.876x" in rows[0].audit and found.recomputed not in rows[0].audit
    assert power.power_rows(ctx, 20, 4, bootstrap_claims=False, findings=fine, specs=published)[0].audit == ""


# ---------------------------------------------------------------- cost
def test_frames_to_train_counts_a_shared_run_directory_once_at_its_largest_budget(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    runs = [RunBudget(a, 1_000_000), RunBudget(a, 2_000_000, 500_000), RunBudget(b, 1_000_000, 1_000_000)]
    assert frames_to_train(runs) == {a: 1_500_000, b: 0}
    assert makespan([3.0, 3.0, 2.0, 2.0, 2.0], 2) == 7.0


def _bench(root: Path, e2e: bool = True) -> Path:
    data = {"hardware": "Test GPU", "device": "cuda",
            "results": [{"algo": a, "batch_size": 8, "speedup": "plain", "update_seconds": 0.5}
                        for a in ("taco", "drqv2")]}
    if e2e:
        data["e2e"] = [{"algo": a, "batch_size": 8, "frames": 1000, "seconds": 10.0} for a in ("taco", "drqv2")]
    path = root / "bench" / "bench-host-cuda.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))
    return path


@pytest.fixture(scope="module")
def tiny_costs(tmp_path_factory):
    root = tmp_path_factory.mktemp("plan")
    _bench(root)
    return root, plan_sweeps(["tiny"], find_bench(root, "cuda"), results_root=root)


def test_device_hours_on_a_synthetic_bench_equal_runs_times_frames_over_fps(tiny_costs):
    root, costs = tiny_costs
    t = totals("tiny", costs, devices=2, slurm_slots=8)
    frames = costs[0].frames
    assert t.runs == len(costs) == 8 and t.to_train == 8 and t.frames == 8 * frames
    assert t.hours == pytest.approx(8 * frames / (1000 / 10.0) / 3600)  # e2e: 1000 frames in 10 s
    assert t.local_hours == pytest.approx(t.hours / 2) and t.slurm_hours == pytest.approx(t.hours / 8)
    assert all(c.host_bytes > 0 and c.device_bytes > 0 for c in costs)
    # without the e2e entries: update-bound, frames per update (update_every_steps x action_repeat) / 0.5 s
    bench = find_bench(root, "cuda", _bench(root / "upd", e2e=False))
    rate = costs[0].frames_per_update / 0.5
    assert totals("tiny", plan_sweeps(["tiny"], bench, results_root=root), 1, 1).hours == \
        pytest.approx(8 * frames / rate / 3600)
    # an e2e entry of another path (`repro bench --e2e --amp`) does not rate a plain run: update-bound again
    path = _bench(root / "amp")
    data = json.loads(path.read_text())
    data["e2e"] = [{**e, "speedup": "amp"} for e in data["e2e"]]
    path.write_text(json.dumps(data))
    amp_only = plan_sweeps(["tiny"], find_bench(root, "cuda", path), results_root=root)
    assert {c.fps_source for c in amp_only} == {"update-bound"}


def test_plan_without_a_bench_file_is_one_line_and_exit_2(tmp_path):
    """The one line names the command that prices every run of the sweep (each of its agents and batch sizes)."""
    res = CliRunner().invoke(app, ["plan", "tiny", "--tasks", "cheetah_run", "--seeds", "1", "--results",
                                   str(tmp_path), "--out", str(tmp_path / "out")], terminal_width=400)
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.output
    assert (f"run `repro bench update --device cuda --agent taco --agent drqv2 --batch 8 --results {tmp_path}` first"
            in lines[0]), lines
    for args in (["plan"], ["plan", "nosuchsweep"], ["plan", "tiny", "--devices", "0"]):
        bad = CliRunner().invoke(app, [*args, "--results", str(tmp_path)])
        assert bad.exit_code == 2 and len(bad.output.strip().splitlines()) == 1, (args, bad.output)


def test_plan_writes_the_table_with_its_assumptions(tiny_costs, tmp_path):
    root, _ = tiny_costs
    res = CliRunner().invoke(app, ["plan", "tiny", "--results", str(root), "--out", str(tmp_path), "--devices", "2"])
    assert res.exit_code == 0, res.output
    table = pd.read_csv(tmp_path / "plan.csv")
    assert list(table["name"]) == ["tiny", "Total"] and (tmp_path / "plan.md").exists()
    assert (tmp_path / "plan.tex").exists() and "Wall-clock" in (tmp_path / "plan.md").read_text()


def test_replay_bytes_without_building_the_buffer_equal_the_buffers_own():
    from repro.data.replay import ReplayBuffer

    buf = ReplayBuffer(500, (3, 84, 84), 6, frame_stack=3, nstep=3, K=3, discount=0.99, seed=0)
    assert ReplayBuffer.bytes_for(500, (3, 84, 84), 6) == buf.nbytes()


def _verdicts(sctx: Context, claim: power.SimClaim, draws: dict) -> tuple[list[str], str]:
    """The claim's rule on ``draws``: every draw's verdict and the evidence (of draw 0), or not enough data in all."""
    try:
        judged = claim.judge(sctx, draws)
    except cl.NotEnoughData as exc:
        return [cl.NO_DATA] * len(next(iter(draws.values()))), str(exc)
    return list(judged.verdicts), judged.evidence


def test_each_claims_rule_judges_one_draw_as_it_judges_that_draw_among_many(ctx):
    """A simulated claim's rule is written once, over a leading draws axis: `repro claims` calls it on the runs as one
    draw, the power simulation on all its draws at once. Each draw's verdict among many is the verdict of that draw
    alone, and the evidence of many draws is that of draw 0 alone, below, at and above the claim's seed minimum, with
    the cells shifted so that verdicts differ, with a cell's seeds kept from runs, and on a tie."""
    rng = np.random.default_rng(0)
    seen: set[str] = set()
    for claim in power.simulated_claims(ctx):
        sims = 6 if claim.reps else 40
        for seeds in (1, 3, 6):
            sctx = power.sim_context(ctx, claim)
            draws = {c.key: c.draw(rng, sims, 0 if c.kind == "fixed" else seeds) for c in claim.cells}
            scale = rng.uniform(0.6, 1.4, size=(sims, 1))  # one method's cells shifted in each draw
            shifted = {k: (v * scale if k[-1] in ("TACO", "TD3+BC+TACO", "CQL+TACO") and v.shape[1] else v)
                       for k, v in draws.items()}
            first = next(iter(shifted))
            kept = {**shifted, first: np.concatenate([np.broadcast_to(shifted[first][:1, :1], (sims, 1)),
                                                      shifted[first][:, 1:]], axis=1)}
            tie = {k: (np.repeat(v[:, :1], v.shape[1], axis=1) if v.shape[1] else v) for k, v in draws.items()}
            for cells in (draws, shifted, kept, tie):
                verdicts, evidence = _verdicts(sctx, claim, cells)
                assert len(verdicts) == sims
                for i in range(sims):
                    one, one_evidence = _verdicts(sctx, claim, {k: a[i:i + 1] for k, a in cells.items()})
                    assert one == [verdicts[i]], (claim.id, seeds, i)
                    if i == 0:
                        assert one_evidence == evidence, (claim.id, seeds)
                seen |= set(verdicts)
            assert power.draw_verdicts(sctx, claim, draws).tolist() == _verdicts(sctx, claim, draws)[0]
    assert {cl.SUPPORTED, cl.REFUTED, cl.NO_DATA} <= seen
    # a tie (TACO's mean equal to DrQ-v2's on every task) is no lead, in one draw as in many: refuted
    claim = next(c for c in power.simulated_claims(ctx) if c.id == "online_beats_drqv2_all")
    sctx = power.sim_context(ctx, claim)
    tie = {c.key: np.full((4, 3), 500.0) for c in claim.cells}
    assert _verdicts(sctx, claim, tie)[0] == [cl.REFUTED] * 4
    assert _verdicts(sctx, claim, {k: v[:1] for k, v in tie.items()})[0] == [cl.REFUTED]


def test_power_given_the_runs_done_keeps_their_values(tmp_path):
    from analysis.load import load_results
    from analysis.paper import DMC9
    from analysis_fixtures import write_run

    for task in DMC9:  # 2 seeds of each method: below the claim's minimum of 3
        for s in range(2):
            write_run(tmp_path, experiment="main", agent="drqv2", task=task, seed=s, final=100.0, frames=1_000_000,
                      eval_every=250_000)
            write_run(tmp_path, experiment="main", agent="taco", task=task, seed=s, final=900.0, frames=1_000_000,
                      eval_every=250_000)
    ctx = Context(results=load_results(tmp_path), reps=50)
    claim = next(c for c in power.simulated_claims(ctx) if c.id == "online_beats_drqv2_all")
    row = power.PowerRow(claim.id, True, "", 3, 6)
    power.condition_row(ctx, claim, row, sims=200, max_seeds=10)
    assert row.done_seeds == 2 and row.now is not None
    assert row.now.supported == 1.0 and row.more_80 == 1  # TACO far ahead in the seeds done: one more seed decides


# ---------------------------------------------------------------- one FPS, every path, the grid of `repro sweep`
def _bench_file(folder: Path, device: str, results: list[dict], e2e: list[dict] | None = None) -> Path:
    from repro.bench.results import FORMAT

    path = folder / "bench" / f"bench-host-{device}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"kind": "online", "format": FORMAT, "hardware": f"Test {device}", "device": device,
                                "results": results, "e2e": e2e or []}))
    return path


def _upd(agent: str, path: str, seconds: float, batch: int = 8) -> dict:
    return {"agent": agent, "batch_size": batch, "speedup": path, "update_seconds": seconds, "frames_per_update": 4}


def test_a_fast_run_is_priced_from_the_fast_entry(tmp_path):
    """`repro plan tiny --set agent.fast=true`: each run's device-hours are its frames over the fast entry's FPS (a
    plan that priced it from the plain entry, as `_speedup` did, is 4x off here)."""
    from repro.launch.spec import Selection

    _bench_file(tmp_path, "cpu", [_upd(a, p, s) for a in ("taco", "drqv2") for p, s in (("plain", 2.0),
                                                                                      ("fast", 0.5))])
    bench = find_bench(tmp_path)
    assert bench.device == "cpu" and "newest bench file" in bench.chosen
    fast = plan_sweeps(["tiny"], bench, Selection(sets=("agent.fast=true",)), results_root=tmp_path, memory=False)
    assert {c.path for c in fast} == {"fast"} and {c.fps_source for c in fast} == {"update-bound"}
    frames = sum(c.frames for c in fast)
    assert totals("tiny", fast, 1, 1).hours == pytest.approx(frames / (4 / 0.5) / 3600)
    plain = plan_sweeps(["tiny"], bench, results_root=tmp_path, memory=False)
    assert {c.path for c in plain} == {"plain"}
    assert totals("tiny", plain, 1, 1).hours == pytest.approx(4 * totals("tiny", fast, 1, 1).hours)
    # the same through the command line: the grid options of `repro sweep`, the device of the newest bench file
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["plan", "tiny", "--set", "agent.fast=true", "--seeds", "1", "--tasks",
                                   "cheetah_run", "--results", str(tmp_path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    row = pd.read_csv(out / "plan.csv").iloc[0]
    one = [c for c in fast if c.task == "cheetah_run" and c.run_dir.name == "seed_1"]
    assert row["runs"] == len(one) == 2 and row["hours"] == pytest.approx(sum(c.frames for c in one) / 8 / 3600)
    assert "device cpu: the device of the newest bench file" in " ".join(res.output.split())


def test_a_run_the_bench_does_not_time_names_the_command_that_would(tmp_path):
    _bench_file(tmp_path, "cuda", [_upd("taco", "plain", 1.0)])
    costs = plan_sweeps(["tiny"], find_bench(tmp_path, "cuda"), results_root=tmp_path, memory=False)
    missing = {c.missing for c in costs if c.missing}
    assert missing == {"repro bench update --device cuda --agent drqv2 --batch 8"}
    amp = plan_sweeps(["tiny"], find_bench(tmp_path, "cuda"), specs_selection(("agent.amp=true",)),
                      results_root=tmp_path, memory=False)
    assert {c.missing for c in amp} == {f"repro bench update --device cuda --agent {a} --batch 8 --amp"
                                        for a in ("taco", "drqv2")}


def specs_selection(sets: tuple[str, ...]):
    from repro.launch.spec import Selection

    return Selection(sets=sets)


def test_a_plugin_online_agent_is_priced(tmp_path):
    """An online agent of a plugin (tests/plugin_example's toy_utd) is priced like a built-in one: `repro bench update
    --agent` times it, so the plan reads its entry (there was a hand list of the agents `repro bench` times)."""
    from repro.config.compose import online_agents

    if "toy_utd" not in online_agents():
        pytest.skip("the example plugin is not installed (pip install -e tests/plugin_example)")
    sweep = tmp_path / "toy.yaml"
    sweep.write_text("name: toy\ndescription: a plugin agent\nartifacts: []\nexperiment: toy\ntasks: [cheetah_run]\n"
                     "agents: [toy_utd]\nseeds: 1\nframes: 400\neval: {every_frames: 200, episodes: 1}\n"
                     "common: [profile=tiny]\nvariants: {base: []}\n")
    _bench_file(tmp_path, "cpu", [_upd("toy_utd", "plain", 0.25)])
    (cost,) = plan_sweeps([str(sweep)], find_bench(tmp_path, "cpu"), results_root=tmp_path, memory=False)
    assert cost.agent == "toy_utd" and not cost.missing
    assert cost.fps == pytest.approx(cost.frames_per_update / 0.25)


def test_t4_and_plan_read_one_fps_from_one_bench_file(tmp_path):
    """The speed tables (T4/T5, the claim `speed`, `repro report`) and `repro plan` give the same FPS for an agent,
    batch size and path of one bench file: the end-to-end entry where there is one, else update-bound."""
    from analysis.load import load_results
    from analysis.speed import speed_measurements

    _bench_file(tmp_path, "cpu", [_upd(a, p, s) for a in ("taco", "drqv2") for p, s in (("plain", 2.0),
                                                                                      ("fast", 0.5))],
                [{"agent": "taco", "batch_size": 8, "speedup": "plain", "frames": 100, "seconds": 40.0}])
    meas = speed_measurements(load_results(tmp_path))
    table = {(m, p): f for m, p, f in zip(meas["method"], meas["speedup"], meas["fps"])}
    assert table == {("TACO", "plain"): 2.5, ("TACO", "fast"): 8.0, ("DrQ-v2", "plain"): 2.0,
                     ("DrQ-v2", "fast"): 8.0}
    assert all(("[fast]" in s) == (p == "fast") for s, p in zip(meas["source"], meas["speedup"]))  # labelled
    bench = find_bench(tmp_path, "cpu")
    for sets in ((), ("agent.fast=true",)):
        for c in plan_sweeps(["tiny"], bench, specs_selection(sets), results_root=tmp_path, memory=False):
            assert c.frames_per_update == 4  # the tiny runs' own frames per update, as the bench's config
            assert c.fps == pytest.approx(table[({"taco": "TACO", "drqv2": "DrQ-v2"}[c.agent], c.path)])


def test_plan_claims_reuses_the_analysis_cache_of_its_out_folder(tmp_path: Path):
    from analysis_fixtures import write_run

    for agent in ("taco", "drqv2"):
        for s in range(2):
            write_run(tmp_path / "runs", experiment="main", agent=agent, task="cheetah_run", seed=s, final=100.0 + s)
    args = ["plan", "--claims", "--results", str(tmp_path / "runs"), "--sims", "20", "--max-seeds", "3",
            "--reps", "50"]
    first = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert first.exit_code == 0, first.output
    assert "runs 0 reused, 4 computed" in first.output and "compose 0 reused" in first.output
    tables = {name: (tmp_path / "out" / name).read_bytes() for name in ("plan_power.csv", "plan_power_cells.csv")}
    second = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert second.exit_code == 0, second.output
    assert "runs 4 reused, 0 computed" in second.output and "compose 0 reused" not in second.output
    assert "compose" in second.output and " 0 computed" in second.output.split("compose")[1].split(";")[0]
    for name, table in tables.items():  # what it reused gives the same tables
        assert (tmp_path / "out" / name).read_bytes() == table
    third = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "nc"), "--no-cache"])
    assert third.exit_code == 0, third.output
    assert not (tmp_path / "nc" / ".cache").exists() and "Cache (" not in third.output


def test_plan_claims_with_a_bench_file_it_cannot_read_is_one_line_and_exit_2(tmp_path: Path):
    """--bench names the file to price with: a missing or malformed one is refused before any work (it was priced in
    frames only, exit 0); with no --bench and no bench file found, the plan prices in frames and says so."""
    from analysis_fixtures import write_run

    write_run(tmp_path / "runs", experiment="main", agent="taco", task="cheetah_run", seed=0, final=100.0)
    (tmp_path / "bad.json").write_text("{bad")
    args = ["plan", "--claims", "--results", str(tmp_path / "runs"), "--sims", "20", "--max-seeds", "3", "--reps", "50"]
    for bench, why in ((tmp_path / "bad.json", "cannot read bench file"), (tmp_path / "none.json", "does not exist")):
        out = CliRunner().invoke(app, [*args, "--bench", str(bench), "--out", str(tmp_path / "out")],
                                 terminal_width=400)
        assert out.exit_code == 2 and out.output.startswith("error: ") and why in out.output, out.output
        assert len(out.output.strip().splitlines()) == 1 and not (tmp_path / "out").exists()
    found = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")], terminal_width=400)
    assert found.exit_code == 0 and "Cost of those seeds in frames only: no `repro bench` file" in found.output


def test_a_kept_composition_equals_composing_and_is_a_fresh_copy(tmp_path: Path):
    from omegaconf import OmegaConf

    from analysis.cache import opened
    from analysis.composed import composed
    from repro.config.compose import compose

    overrides = ["agent=taco", "task=walker_run", "seed=3"]
    with opened(tmp_path) as first:
        cfg = composed(overrides)
        cfg.seed = 99  # the planner sets values in what it gets
        assert composed(overrides).seed == 3
    assert first.misses == {"compose": 1} and first.hits == {"compose": 1}
    with opened(tmp_path) as second:
        again = composed(overrides)
    assert second.hits == {"compose": 1}
    assert OmegaConf.to_container(again) == OmegaConf.to_container(compose(overrides))


# ---------------------------------------------------------------- every run counted, packing, one memory figure
MIX = """name: mix
description: DrQ-v2 at two batch sizes on two paths
artifacts: []
experiment: mix
tasks: [cheetah_run]
agents: [drqv2]
seeds: 1
frames: 400
eval: {every_frames: 200, episodes: 1}
common: [profile=tiny]
variants: {base: [], big: [agent.batch_size=16, agent.fast=true]}
"""


def _parse_bench(command: str) -> tuple[str, dict]:
    """A `repro bench SUB ...` command as printed, parsed by `repro bench`'s own command line (click): (SUB, its
    parameters)."""
    import shlex

    from typer.main import get_command

    words = shlex.split(command)
    assert words[:2] == ["repro", "bench"], command
    sub = get_command(bench_app()).commands["bench"].commands[words[2]]  # type: ignore[attr-defined]
    return words[2], sub.make_context(words[2], words[3:]).params


def _timed(params: dict) -> set[tuple[str, int, str]]:
    """Every (agent, batch, path) a parsed `repro bench update` times: each agent at each batch on each path."""
    paths = {"plain", *(p for p, key in (("amp", "amp"), ("compile", "compile_"), ("fast", "fast")) if params[key])}
    return {(a, b, p) for a in params["agent"] for b in params["batch"] for p in paths}


def test_the_headline_counts_every_run_and_the_packing_is_bound_by_host_memory(tmp_path, monkeypatch):
    """Issue 50: the plan headlined the priced runs' hours as the sweep's cost (the unpriced ones in a table cell), and
    gave '<= 569 runs per device' while each run needed 19.8 GiB of host memory. Now the headline counts every run:
    those priced, with their hours, and those not priced by setting with the one `repro bench` command that prices
    them all, which, parsed back by `repro bench`'s own command line, times every unpriced (agent, batch, path) and,
    run (its timings stood in for), leaves none unpriced; an entry timed under load is flagged; runs per device is
    min(device memory / device bytes, host memory / host bytes) and the advice names --runs-per-gpu."""
    from repro.bench import cli as bench_cli
    from repro.bench import results as br
    from repro.bench.results import FORMAT
    from repro.launch.cost import GB, Packing, packing, price, unpriced_runs
    from repro_app.plan import runs_per_device
    from test_bench import _fake_time_update

    assert packing(GB, 10 * GB, 80 * GB, 64 * GB) == Packing(6, "host memory")
    assert packing(GB, 10 * GB, 80 * GB, 64 * GB, devices=2) == Packing(3, "host memory")  # two devices share it
    assert packing(20 * GB, GB, 80 * GB, 512 * GB, measured=False) == Packing(4, "device memory", upper=True)
    assert packing(20 * GB, GB, None, None) == Packing(None)
    assert runs_per_device(Packing(4, "device memory", upper=True)) == "<= 4 (device memory: networks only)"
    sweep, root = tmp_path / "mix.yaml", tmp_path / "runs"
    sweep.write_text(MIX)
    bench = root / "bench" / br.file_name(br.ONLINE, "cpu")
    bench.parent.mkdir(parents=True)
    bench.write_text(json.dumps({"kind": "online", "format": FORMAT, "hardware": "Test cpu", "device": "cpu",
                                 "results": [{**_upd("drqv2", "plain", 0.5), "load": 9.0, "cores": 2}]}))
    costs = plan_sweeps([str(sweep)], find_bench(root), results_root=root, memory=False)
    total = totals("Total", costs, 1, 1)
    assert (total.runs, total.to_train, total.priced, total.unpriced) == (2, 2, 1, 1)
    assert total.unpriced_settings == {"drqv2 B16 fast": 1}
    gb = 3.5 * max(c.host_bytes for c in costs) / GB  # room for three runs' replays
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["plan", str(sweep), "-r", str(root), "-o", str(out), "--device-memory-gb", "80",
                                   "--host-memory-gb", f"{gb:.9f}"], terminal_width=400)
    assert res.exit_code == 0, res.output
    caption = (out / "plan.md").read_text().splitlines()[0]
    assert "Cost of mix: 2 runs, 2 to train; 1 priced, " in caption and "1 not priced (drqv2 B16 fast: 1)" in caption
    (command,) = re.findall(r"`(repro bench [^`]+)`", caption)
    assert command == f"repro bench update --device cpu --agent drqv2 --batch 16 --fast --results {root}"
    sub, params = _parse_bench(command)
    assert sub == "update" and params["device"] == "cpu" and params["results_root"] == root
    assert {(c.agent, c.batch_size, c.path) for c in unpriced_runs(costs)} <= _timed(params)
    notes = " ".join(res.output.split())
    assert "Timed under load" in notes and "drqv2 B8 (load 9.0 on 2 cores)" in notes
    table = pd.read_csv(out / "plan.csv")
    assert list(table["runs_per_device"]) == ["3 (host memory)"] * 2 and list(table["runs_per_device_n"]) == [3, 3]
    assert "bound by the host memory" in notes and "`repro sweep mix --gpus 0 --runs-per-gpu 3` packs them" in notes
    # run the command (its timings stood in for): every run is priced now
    monkeypatch.setattr(bench_cli, "time_update", _fake_time_update(defaultdict(lambda: 0.25)))
    ran = CliRunner().invoke(bench_app(), ["bench", *command.split()[2:]])
    assert ran.exit_code == 0, ran.output
    again = find_bench(root)
    for c in costs:
        c.fps, c.missing = None, ""
        price(c, again)
    assert not unpriced_runs(costs) and totals("Total", costs, 1, 1).unpriced == 0
    bad = CliRunner().invoke(app, ["plan", str(sweep), "-r", str(root), "--host-memory-gb", "0"])
    assert bad.exit_code == 2 and "--host-memory-gb > 0" in bad.output


def test_docs_plan_names_the_command_that_prices_main_and_one_host_memory_figure():
    """docs/plan.md's `repro bench` command is the one `repro plan main` names: every agent, batch and path of main
    (A-LIX, and DrQ-v2 and A-LIX at 512 on walker_run, included). A run's host memory is its replay at capacity: the
    figure the plan prints for main's 1M replay is the one sweeps/launchers/example.yaml (it said ~30 GB) and the docs
    quote."""
    from repro.launch import spec as specs
    from repro.launch.cost import bench_commands
    from repro_app.plan import _gb

    costs = plan_sweeps(["main"], None, specs.selection(seeds=1), memory=False)  # the seeds do not change a setting
    (command,) = bench_commands(costs, "cuda", Path("runs"))
    assert {(c.agent, c.batch_size) for c in costs} >= {("alix", 256), ("drqv2", 512), ("taco", 1024)}
    root = Path(__file__).resolve().parents[1]
    assert command in " ".join((root / "docs" / "plan.md").read_text().split())
    assert {(c.agent, c.batch_size, c.path) for c in costs} <= _timed(_parse_bench(command)[1])
    figure = _gb(max(c.host_bytes for c in costs))
    assert figure == "19.8 GiB"
    for doc in ("sweeps/launchers/example.yaml", "docs/plan.md"):
        text = (root / doc).read_text()
        assert figure in text and "30 GB" not in text, doc


def test_verify_dry_run_on_a_cpu_machine_never_suggests_cuda(tmp_path, monkeypatch):
    """`repro verify --dry-run` on a machine without a GPU said so, then told the user to run `repro bench update
    --device cuda`: it names the CPU bench of the CPU check's run now (even with a CUDA bench file under the root), and
    the CPU check's one measured time."""
    from repro_app import verify_cli
    from repro_app.verify_cli import CPU_CHECK_TIME

    monkeypatch.setattr(verify_cli, "_has_cuda", lambda: False)
    _bench_file(tmp_path, "cuda", [_upd("drqv2", "fast", 0.05, batch=256)])
    res = CliRunner().invoke(app, ["verify", "--dry-run", "-r", str(tmp_path)], terminal_width=400)
    assert res.exit_code == 0, res.output
    out = " ".join(res.output.split())
    assert "--device cuda" not in out and CPU_CHECK_TIME in out, out
    assert (f"`repro bench update --device cpu --agent drqv2 --batch 256 --fast --results {tmp_path}` times these "
            "runs here") in out, out
