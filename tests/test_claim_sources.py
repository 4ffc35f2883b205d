"""Claims as specs (issue 36): each claim of claims.csv has exactly one spec (analysis.claims.SPECS), `repro claims`,
`repro plan --claims` and the report list the same claims, and the paper's printed numbers a claim compares with or
quotes are read from the packaged paper data (repro_data/paper/), not repeated as literals in analysis/claims/."""

from __future__ import annotations

import io
import re
import shutil
import tokenize
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import audit, power
from analysis import cells as cells_module
from analysis import claims as cl
from analysis.claim_budget import BUDGETS_CSV
from analysis.claims import ablations, online
from analysis.context import Context
from analysis.load import Results
from analysis.paper import DMC9, OFFLINE_TASKS, PaperData
from analysis.paper_tex import header


def _ctx(paper: PaperData) -> Context:
    return Context(results=Results(Path("."), pd.DataFrame(), pd.DataFrame()), paper=paper, reps=200)


def _draws(values: dict[tuple, np.ndarray]) -> cl.Draws:
    """The runs' cells as the one draw a rule reads."""
    return cl.one_draw(values)


def test_offline_average_reads_table_3s_printed_averages_from_the_paper_data(tmp_path):
    packaged = PaperData()
    avg = packaged.offline_average
    assert cl.offline_printed(packaged) == {
        m: float(avg.loc[avg["method"] == m, "average_normalized"].iloc[0]) for m in cl.OFFLINE_AVERAGED}
    # another copy of the paper data with other printed averages: the rule reads those
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    edited = avg.assign(average_normalized=np.where(avg["method"] == "CQL", 10.0, avg["average_normalized"]))
    edited.to_csv(root / "offline_average.csv", index=False)
    edited_paper = PaperData(root)
    assert cl.offline_printed(edited_paper)["CQL"] == 10.0
    # every method's runs at its printed average: inside the CI; CQL's printed value moved to 10: outside
    pairs = [(t, d) for t in OFFLINE_TASKS for d in ("medium", "medium-replay", "full-replay")]
    cells = _draws({(t, d, m): np.full(3, p) + np.linspace(-1, 1, 3)
                    for m, p in cl.offline_printed(packaged).items() for t, d in pairs})

    def judge(paper: PaperData) -> cl.Judgement:
        return cl.offline_average_rule(cells, cl.offline_printed(paper), min_seeds=3, budget="x", reps=200, seed=0)

    verdict, evidence = judge(edited_paper).first
    assert verdict == cl.REFUTED and "vs 10.0 (outside)" in evidence
    assert judge(packaged).first[0] == cl.SUPPORTED


def test_the_objectives_taco_is_compared_with_are_table_2s(tmp_path):
    packaged = PaperData()
    assert packaged.repr_others == tuple(m for m in dict.fromkeys(packaged.repr_objectives["method"])
                                         if m not in ("TACO", "DrQ-v2"))
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    t2 = packaged.repr_objectives
    t2[t2["method"] != "ATC"].to_csv(root / "representation_objectives_table.csv", index=False)
    without_atc = PaperData(root)
    assert "ATC" not in without_atc.repr_others and "SPR" in without_atc.repr_others
    # TACO ahead of every objective but ATC on every task: refuted by Table 2 as packaged, supported without ATC
    cells = {}
    for t in cl.REPR_TASKS:
        cells[(t, "TACO")] = np.full(3, 500.0)
        for m in packaged.repr_others:
            cells[(t, m)] = np.full(3, 600.0 if m == "ATC" else 400.0)
    spec = cl.SPEC_OF["vs_repr_objectives"].simulation
    assert spec is not None
    assert spec.judge(_ctx(packaged), _draws(cells)).first[0] == cl.REFUTED
    assert spec.judge(_ctx(without_atc), _draws(cells)).first[0] == cl.SUPPORTED
    # T2's caption names the objectives of the table it reads
    from paper_figures.t2_repr_objectives import render

    captions = []
    for i, paper in enumerate((packaged, without_atc)):
        ctx = _ctx(paper)
        ctx.out_dir = tmp_path / f"t2_{i}"
        captions.append(render(ctx).caption)
    assert "other representation objectives (SPR, ATC, DRIML), all on" in captions[0]
    assert "other representation objectives (SPR, DRIML), all on" in captions[1]


def test_table_2s_latex_columns_are_its_csvs_methods_in_order(tmp_path):
    """The audit reads Table 2's LaTeX columns in the order of its CSV's methods; the LaTeX header says the same."""
    packaged = PaperData()
    assert header(packaged.tex, "tab:spr_table") == list(packaged.repr_methods) == ["TACO", "SPR", "ATC", "DRIML",
                                                                                    "DrQ-v2"]
    assert header(packaged.tex, "tab:online_table")[:2] == ["TACO", "DrQv2"]  # \ours expanded, as printed
    columns = [f for f in audit.check_transcription(packaged) if f.description == "method columns in order"]
    assert [f.match for f in columns] == [True]
    # a CSV with SPR and ATC named the other way round: read in the CSV's order, the LaTeX cells agree with it, so
    # only the header check finds the swap
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    t2 = packaged.repr_objectives
    swap = {"SPR": "ATC", "ATC": "SPR"}
    t2.assign(method=t2["method"].map(lambda m: swap.get(m, m))).to_csv(
        root / "representation_objectives_table.csv", index=False)
    findings = [f for f in audit.check_transcription(PaperData(root)) if f.where == "T2 CSV vs LaTeX"]
    assert findings[0].description == "method columns in order" and not findings[0].match
    assert (findings[0].printed, findings[0].recomputed) == ("TACO, ATC, SPR, DRIML, DrQ-v2",
                                                             "TACO, SPR, ATC, DRIML, DrQ-v2")
    assert [f.match for f in findings[1:]] == [True]


# ---------------------------------------------------------------- one spec per claim, the same claims everywhere
def _paper_copy(tmp_path: Path, claims: pd.DataFrame) -> PaperData:
    root = tmp_path / "paper"
    shutil.copytree(PaperData().root, root)
    claims.to_csv(root / "claims.csv", index=False)
    return PaperData(root)


def test_every_claim_has_exactly_one_spec_that_is_simulated_or_says_why_not():
    paper = PaperData()
    ids = list(paper.claims["id"])
    judged = [s.claim_id for s in cl.SPECS if not s.reading_of]
    assert sorted(judged) == sorted(ids) and len(set(judged)) == len(judged)  # each claim of claims.csv once
    assert [s.id for s in cl.claim_specs(paper) if not s.reading_of] == ids  # listed in claims.csv's order
    assert len({s.id for s in cl.SPECS}) == len(cl.SPECS)
    assert all(s.reading_of in ids and s.note for s in cl.SPECS if s.reading_of)
    for s in cl.SPECS:
        assert (s.simulation is None) == bool(s.not_simulated), s.id  # one or the other, never both or neither
        assert s.rule and callable(s.check), s.id
    # each claim's budget: one row of claim_budgets.csv per claim, none for a claim that does not exist
    budgets = pd.read_csv(BUDGETS_CSV)
    assert sorted(budgets["id"]) == sorted(ids)


def test_claim_specs_refuses_a_claim_without_a_spec_and_a_spec_without_its_claim(tmp_path):
    claims = PaperData().claims
    extra = pd.concat([claims, pd.DataFrame([{"id": "new_claim", "where": "x", "claim": "y", "evidence": "z"}])])
    with pytest.raises(ValueError, match=r"no spec for \['new_claim'\]"):
        cl.claim_specs(_paper_copy(tmp_path / "a", extra))
    # online_avg_gain gone: its spec and the spec of its reading against the published curves have no claim
    with pytest.raises(ValueError, match=r"no claim for \['online_avg_gain', 'online_avg_gain_vs_published'\]"):
        cl.claim_specs(_paper_copy(tmp_path / "b", claims[claims["id"] != "online_avg_gain"]))


def test_repro_claims_plan_and_the_report_list_the_same_claims(tmp_path):
    from repro_app.report import _claims_section

    ctx = _ctx(PaperData())
    ctx.out_dir = tmp_path
    listed = [s.id for s in cl.claim_specs(ctx.paper)]
    assert listed[:2] == ["online_avg_gain", cl.PUBLISHED_GAIN_ID]  # a reading right after its claim
    verdicts = cl.evaluate_claims(ctx)
    cl.write_claims(ctx, verdicts)  # what `repro claims` writes
    assert list(pd.read_csv(tmp_path / "claims.csv")["id"]) == listed
    rows = power.power_rows(ctx, sims=4, max_seeds=3, verdicts=verdicts, bootstrap_claims=False)
    power.write_power(tmp_path, rows, 4, 0, 3)  # what `repro plan --claims` and the report's power section write
    assert list(pd.read_csv(tmp_path / "plan_power.csv")["id"]) == listed
    assert {r.id for r in rows if r.simulated} | {"offline_average"} == {s.id for s in cl.SPECS if s.simulation}
    assert all(r.reason == cl.SPEC_OF[r.id].not_simulated for r in rows if cl.SPEC_OF[r.id].not_simulated)
    section = _claims_section(ctx, verdicts)  # the report's claims table
    shown = [line.split("|")[1].strip() for line in section.splitlines() if line.startswith("| ")][1:]
    assert shown == listed


def test_the_printed_numbers_the_evidence_quotes_are_the_paper_datas(tmp_path):
    paper = PaperData()
    assert cl.speed_printed(paper) == ("(paper 3.6, from its table 130/35 = 3.71)",
                                       "(paper B256 94, B512 65, B1024 35)")
    root = tmp_path / "paper"
    shutil.copytree(paper.root, root)
    te = paper.time_efficiency
    te.assign(fps=np.where((te["method"] == "TACO") & (te["batch_size"] == 1024), 26, te["fps"])).to_csv(
        root / "time_efficiency.csv", index=False)
    assert cl.speed_printed(PaperData(root)) == ("(paper 3.6, from its table 130/26 = 5.00)",
                                                 "(paper B256 94, B512 65, B1024 26)")
    # Table 1's ratio of 9-task means: 1.397 as packaged; TACO's means doubled in a copy, 2.794
    cells = _gain_cells(500.0, 400.0)
    assert "Table 1 gives 1.397)" in online._judge_gain(_ctx(paper), cells).evidence
    doubled = PaperData()
    table1 = doubled.online
    doubled.__dict__["online"] = table1.assign(mean=np.where(table1["method"] == "TACO", 2 * table1["mean"],
                                                             table1["mean"]))
    assert "Table 1 gives 2.794)" in online._judge_gain(_ctx(doubled), cells).evidence


def _gain_cells(taco: float, drq: float, draws: int = 1) -> cl.Draws:
    """online_avg_gain's cells, every seed of a method at one value, in ``draws`` draws."""
    return {(t, m): np.full((draws, 3), v) for t in DMC9 for m, v in (("TACO", taco), ("DrQ-v2", drq))}


# ---------------------------------------------------------------- the numbers of the paper's prose
_NUMBER_WORDS = {"none": 0.0}  # how claims.csv writes a number in words


def test_each_number_of_the_prose_is_quoted_from_its_claim_and_the_latex():
    paper = PaperData()
    numbers = paper.claim_numbers
    assert not numbers.duplicated(["claim", "name"]).any()
    text = dict(zip(paper.claims["id"], paper.claims["claim"]))
    tex = " ".join(paper.tex.split())
    for r in numbers.itertuples(index=False):
        assert r.quote in text[r.claim], (r.claim, r.quote)  # the words are the claim's, in claims.csv
        assert " ".join(r.tex.split()) in tex, (r.claim, r.tex)  # and the paper says it in its LaTeX
        written = str(r.written)
        assert re.search(rf"(?<![\w.]){re.escape(written)}(?!\d|\.\d)", r.quote), (r.claim, written)
        assert r.value == _NUMBER_WORDS.get(written, None) or (written not in _NUMBER_WORDS
                                                                and float(written) == r.value), (r.claim, r.name)
    assert paper.claim_number("speed", "slowdown") == 3.6
    with pytest.raises(KeyError, match="no number 'x' of claim 'speed'"):
        paper.claim_number("speed", "x")


def test_the_rules_and_cells_read_the_numbers_of_the_prose_from_the_paper_data(tmp_path):
    packaged = PaperData()
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    edited_values = {("online_avg_gain", "gain"): 1.5, ("speed", "slowdown"): 5.0,
                     ("manipulator", "taco_solved"): 2.0, ("manipulator", "seeds"): 4.0}
    numbers = packaged.claim_numbers.copy()
    numbers["value"] = [edited_values.get((c, n), v) for c, n, v in zip(numbers["claim"], numbers["name"],
                                                                         numbers["value"])]
    numbers.to_csv(root / "claim_numbers.csv", index=False)
    edited = PaperData(root)
    # online_avg_gain: 1.4 less the tolerance as packaged, 1.5 less it in the copy; a ratio of 1.35 between them
    assert (cl.gain_bar(packaged), cl.gain_bar(edited)) == (1.3, 1.4)
    assert cl.SPEC_OF["online_avg_gain"].rule_text(edited).startswith(
        "mean over the 9 tasks of TACO / DrQ-v2 >= 1.4 (about 1.5x, tolerance 0.1)")
    assert ">= 1.4; CI" in cl.SPEC_OF[cl.PUBLISHED_GAIN_ID].rule_text(edited)
    verdict, evidence = online._judge_gain(_ctx(edited), _gain_cells(540.0, 400.0)).first
    assert verdict == cl.REFUTED and "paper: 1.5x" in evidence
    assert online._judge_gain(_ctx(packaged), _gain_cells(540.0, 400.0)).first[0] == cl.SUPPORTED
    draws = _gain_cells(540.0, 400.0, draws=2)  # the power simulation's draws: the same rule, every draw at once
    assert list(online._judge_gain(_ctx(edited), draws).verdicts) == [cl.REFUTED] * 2
    assert list(online._judge_gain(_ctx(packaged), draws).verdicts) == [cl.SUPPORTED] * 2
    # speed: the ratio the rule and its evidence quote
    assert "within ±25% of 5," in cl.SPEC_OF["speed"].rule_text(edited)
    assert cl.speed_printed(edited)[0] == "(paper 5, from its table 130/35 = 3.71)"
    speed = next(f for f in audit.check_t4_vs_t5(edited) if f.check == "speed_ratio")
    assert speed.printed == "5" and "'about 5 times slower" in speed.description
    # manipulator: appendix G's counts are the cells' proportions, the rule's and the note's numbers
    sim = cl.SPEC_OF["manipulator"].simulation
    assert sim is not None
    cells = {c.key: c for c in sim.sources(_ctx(edited), 30e6)}
    assert (cells[("TACO",)].mean, cells[("DrQ-v2",)].mean) == (0.5, 0.0)
    assert cells[("TACO",)].source == "appendix G: 2 of 4 seeds solve"
    assert [c.source for c in sim.sources(_ctx(packaged), 30e6)] == ["appendix G: 3 of 6 seeds solve",
                                                                     "appendix G: 0 of 6 seeds solve"]
    assert "(paper 2/4)" in cl.SPEC_OF["manipulator"].rule_text(edited)
    assert sim.notes_text(edited)[0].startswith("DrQ-v2's 0 of 4 taken as a solve probability of 0 (its 95% upper "
                                                "bound is 53%)")
    assert "(its 95% upper bound is 39%)" in sim.notes_text(packaged)[0]


def _edited_paper(tmp_path: Path, values: dict[tuple[str, str], float]) -> PaperData:
    """A copy of the packaged paper data with some numbers of claim_numbers.csv changed."""
    packaged = PaperData()
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    numbers = packaged.claim_numbers.copy()
    numbers["value"] = [values.get((c, n), v) for c, n, v in zip(numbers["claim"], numbers["name"], numbers["value"])]
    numbers.to_csv(root / "claim_numbers.csv", index=False)
    return PaperData(root)


def test_the_audit_reads_section_5_1s_action_representation_percentages(tmp_path):
    packaged = PaperData()
    edited = _edited_paper(tmp_path, {("action_repr_gain", "gain_low_percent"): 10.0,
                                      ("action_repr_gain", "gain_high_percent"): 80.0,
                                      ("no_action_repr_vs_drqv2", "quadruped_run_percent"): 30.0,
                                      ("no_action_repr_vs_drqv2", "reacher_hard_percent"): 40.0})
    assert cl.action_repr_printed(packaged) == ("(paper: +12.2% quadruped_run ... +70.4% hopper_hop)",
                                                "(paper: +18% quadruped_run, +51% reacher_hard)")
    assert cl.action_repr_printed(edited) == ("(paper: +10% quadruped_run ... +80% hopper_hop)",
                                              "(paper: +30% quadruped_run, +40% reacher_hard)")
    before = {f.check: f for f in audit.check_action_repr_text(packaged)}
    after = {f.check: f for f in audit.check_action_repr_text(edited)}
    assert before["action_repr_quadruped"].description == ("quadruped_run TACO w/o action repr implied two ways: "
                                                           "TACO/1.122 and DrQ-v2 x 1.18 (within 2%)")
    assert "TACO/1.1 and DrQ-v2 x 1.3 (within 2%)" in after["action_repr_quadruped"].description
    # Table 1's quadruped_run means agree within 2% through 12.2% and 18%, not through 10% and 30%
    assert before["action_repr_quadruped"].match and not after["action_repr_quadruped"].match
    assert (before["action_repr_reacher"].printed, after["action_repr_reacher"].printed) == ("12.2% to 70.4%",
                                                                                           "10% to 80%")
    assert "DrQ-v2 x 1.51 implies" in before["action_repr_reacher"].description
    assert "DrQ-v2 x 1.4 implies" in after["action_repr_reacher"].description
    # reacher_hard: 51% over DrQ-v2 leaves TACO 2.2% ahead (outside 12.2%-70.4%); 40% over it, 10.3% (inside 10%-80%)
    assert before["action_repr_reacher"].recomputed.startswith("2.2%") and not before["action_repr_reacher"].match
    assert after["action_repr_reacher"].recomputed.startswith("10.3%") and after["action_repr_reacher"].match


def test_the_claims_evidence_reads_reacher_speeds_steps_and_the_action_representation_percentages(tmp_path):
    from analysis.load import load_results
    from analysis_fixtures import write_run

    runs = tmp_path / "runs"
    frames = 1_500_000  # reacher_speed's budget (claim_budgets.csv); the action_repr claims' is 1M
    for seed in range(3):
        for agent, curve in (("taco", [0, 500, 950, 950]), ("drqv2", [0, 300, 600, 950])):
            write_run(runs, experiment="main", agent=agent, task="reacher_hard", seed=seed, final=curve[-1],
                      frames=frames, eval_every=frames // 3, curve=curve)
        write_run(runs, experiment="action_repr", agent="taco", task="reacher_hard", seed=seed, final=700.0 + seed,
                  action_encoder=False, frames=1_000_000, eval_every=500_000, variant="no_action_repr")
        for task in ("quadruped_run", "hopper_hop"):
            for agent, encoder, final in (("taco", None, 600.0), ("taco", False, 500.0), ("drqv2", None, 400.0)):
                write_run(runs, experiment="action_repr" if encoder is False else "main", agent=agent, task=task,
                          seed=seed, final=final + seed, action_encoder=encoder, frames=1_000_000,
                          eval_every=500_000, variant="no_action_repr" if encoder is False else "base")
    results = load_results(runs)
    edited = _edited_paper(tmp_path, {("reacher_speed", "taco_steps_millions"): 0.5,
                                      ("reacher_speed", "drqv2_steps_millions"): 2.0,
                                      ("action_repr_gain", "gain_high_percent"): 80.0,
                                      ("no_action_repr_vs_drqv2", "reacher_hard_percent"): 40.0})
    papers = (PaperData(), edited)
    # each claim's check at its budget, as evaluate_claims runs it
    speed = [online._reacher_speed(Context(results=results, paper=p, reps=50, budget=frames)) for p in papers]
    assert speed == [(cl.SUPPORTED, "target 902: TACO at 1.00M, DrQ-v2 1.50M (paper: 0.75M vs 1.5M)"),
                     (cl.SUPPORTED, "target 902: TACO at 1.00M, DrQ-v2 1.50M (paper: 0.5M vs 2M)")]
    assert cl.SPEC_OF["reacher_speed"].rule_text(edited) == (
        "on reacher_hard, with curves cut at the budget (1.5M) and target = 95% of TACO's best mean-curve value: TACO "
        "reaches it within 2/3 of the budget (1.0M frames) and DrQ-v2 needs >= 1.5x as many frames (or never does)")
    at_1m = [Context(results=results, paper=p, reps=50, budget=1_000_000) for p in papers]
    gain = [ablations._action_repr_gain(c) for c in at_1m]
    assert [v for v, _ in gain] == [cl.SUPPORTED, cl.SUPPORTED]
    assert "(paper: +12.2% quadruped_run ... +70.4% hopper_hop)" in gain[0][1]
    assert "(paper: +12.2% quadruped_run ... +80% hopper_hop)" in gain[1][1]
    no_repr = [ablations._no_repr_vs_drqv2(c) for c in at_1m]
    assert no_repr[0][1].endswith("(paper: +18% quadruped_run, +51% reacher_hard)")
    assert no_repr[1][1].endswith("(paper: +18% quadruped_run, +40% reacher_hard)")


def test_the_action_repeat_claim_reads_the_best_k_of_appendix_b(tmp_path):
    from analysis.load import load_results
    from analysis_fixtures import write_run

    packaged = PaperData()
    edited = _edited_paper(tmp_path, {("action_repeat", "best_k_at_repeat_2"): 5.0,
                                      ("action_repeat", "best_k_at_repeat_4"): 5.0})
    assert cl.best_k_printed(packaged) == {1: 5, 2: 3, 4: 1} and cl.best_k_printed(edited) == {1: 5, 2: 5, 4: 5}
    assert cl.SPEC_OF["action_repeat"].rule_text(packaged) == ("on hopper_hop the K in {1,3,5} with the highest mean "
                                                               "is 5 at action repeat 1, 3 at 2 and 1 at 4")
    assert cl.SPEC_OF["action_repeat"].rule_text(edited).endswith("is 5 at action repeat 1, 5 at 2 and 5 at 4")
    runs = tmp_path / "runs"
    for ar in cl.ACTION_REPEATS:
        for k in cl.REPEAT_HORIZONS:
            for seed in range(3):
                write_run(runs, experiment="action_repeat", agent="taco", task="hopper_hop", K=k, action_repeat=ar,
                          variant=f"ar{ar}_K{k}", seed=seed, final=100.0 * k + seed, frames=1_000_000,
                          eval_every=500_000)  # K=5 best at every action repeat
    results = load_results(runs)
    packaged_v, edited_v = (ablations._action_repeat(Context(results=results, paper=p, reps=50, budget=1_000_000))
                            for p in (packaged, edited))
    assert packaged_v == (cl.REFUTED, "best K: AR1: K=5, AR2: K=5, AR4: K=5 (paper: AR1 K=5, AR2 K=3, AR4 K=1)")
    assert edited_v == (cl.SUPPORTED, "best K: AR1: K=5, AR2: K=5, AR4: K=5 (paper: AR1 K=5, AR2 K=5, AR4 K=5)")
    # a horizon K is a whole number: claim_integer refuses one written with a fraction
    assert packaged.claim_integer("manipulator", "seeds") == 6
    with pytest.raises(ValueError, match="'taco_steps_millions' of claim 'reacher_speed' is 0.75, not a whole"):
        packaged.claim_integer("reacher_speed", "taco_steps_millions")


def test_no_number_of_the_prose_is_a_literal_in_the_code():
    """The prose's non-integer numbers (1.4, 3.6, 0.75, 12.2, 70.4) and the factors its percentages give (1.122,
    1.18, 1.51, ...) appear in the code only as the paper data gives them: no number literal of analysis/claims/,
    cells.py, audit.py, power.py or the F3 and F9 figures is one of them (comments and docstrings may quote them).
    DrQ-v2's "about 1.5M" steps on reacher_hard is left out: 1.5 is also REACHER_DRQ_FACTOR, this project's own bar
    (the paper's 2x less a margin), and test_the_claims_evidence_reads_reacher_speeds_steps... shows the evidence
    reads the paper's."""
    numbers = PaperData().claim_numbers
    decimals = {str(w) for w in numbers["written"] if "." in str(w)}
    assert decimals == {"1.4", "3.6", "0.75", "1.5", "12.2", "70.4"}
    percents = numbers.loc[numbers["name"].str.endswith("_percent"), "value"]
    factors = {f"{1 + p / 100:g}" for p in percents} | {f"{p / 100:g}" for p in percents}
    assert {"1.122", "1.18", "1.51", "0.122", "0.704"} <= factors
    assert cl.REACHER_DRQ_FACTOR == 1.5
    forbidden = (decimals - {"1.5"}) | factors
    from paper_figures import f3_action_repr, f9_action_repeat

    claims = sorted(Path(cl.__file__).parent.glob("*.py"))  # every module of the claims package
    assert len(claims) > 1
    for path in (*claims, *(Path(m.__file__) for m in (cells_module, audit, power, f3_action_repr, f9_action_repeat))):
        source = path.read_text(encoding="utf-8")
        literals = {t.string for t in tokenize.generate_tokens(io.StringIO(source).readline)
                    if t.type == tokenize.NUMBER}
        assert not literals & forbidden, (path.name, literals & forbidden)


def test_the_budgets_wordings_take_the_prose_numbers_from_the_paper_data(tmp_path):
    """claim_budgets.csv's holds / fails wordings (shown in an indicative reading) name the prose's numbers as
    {fields} of claim_numbers.csv, filled in from the paper data where they are shown."""
    packaged = PaperData()
    budgets = pd.read_csv(BUDGETS_CSV, keep_default_na=False)
    decimals = {str(w) for w in packaged.claim_numbers["written"] if "." in str(w)}
    for r in budgets.itertuples(index=False):
        for words in (r.holds, r.fails):
            shown = cl.budget_words(packaged, r.id, words)
            assert "{" not in shown and "}" not in shown, (r.id, shown)
            assert not any(re.search(rf"(?<![\w.]){re.escape(d)}(?!\d)", words) for d in decimals), (r.id, words)
    gain = budgets.set_index("id").loc["online_avg_gain"]
    speed = budgets.set_index("id").loc["speed"]
    assert [cl.budget_words(packaged, "online_avg_gain", w) for w in (gain.holds, gain.fails)] == [
        "TACO about 1.4x DrQ-v2", "TACO under 1.3x DrQ-v2"]
    edited = _edited_paper(tmp_path, {("online_avg_gain", "gain"): 1.5, ("speed", "slowdown"): 5.0})
    assert [cl.budget_words(edited, "online_avg_gain", w) for w in (gain.holds, gain.fails)] == [
        "TACO about 1.5x DrQ-v2", "TACO under 1.4x DrQ-v2"]
    assert [cl.budget_words(edited, "speed", w) for w in (speed.holds, speed.fails)] == [
        "TACO B1024 about 5x slower", "ratio off 5x"]
    with pytest.raises(KeyError, match="slowdown"):
        cl.budget_words(packaged, "online_avg_gain", "about {slowdown}x")


def test_f3_and_f9_take_the_prose_numbers_from_the_paper_data(tmp_path):
    """F3's implied values of TACO w/o action repr (Table 1 and section 5.1's percentages) and F9's caption (appendix
    B's best K) follow the paper data."""
    from paper_figures import f3_action_repr, f9_action_repeat

    edited = _edited_paper(tmp_path, {("action_repr_gain", "gain_high_percent"): 80.0,
                                      ("action_repeat", "best_k_at_repeat_4"): 3.0})
    assert f3_action_repr.implied_no_repr(PaperData())["hopper_hop"][1] == "261/1.704"
    assert f3_action_repr.implied_no_repr(edited)["hopper_hop"][1] == "261/1.8"
    key = {"task": "hopper_hop", "label": "TACO w/o action repr"}
    assert f3_action_repr.paper_value(_ctx(PaperData()), key) == (153.2, None)  # 261 / 1.704
    assert f3_action_repr.paper_value(_ctx(edited), key) == (145.0, None)  # 261 / 1.8
    captions = []
    for i, paper in enumerate((PaperData(), edited)):
        ctx = _ctx(paper)
        ctx.out_dir = tmp_path / f"figures_{i}"
        captions.append((f3_action_repr.render(ctx).caption, f9_action_repeat.render(ctx).caption))
    assert "(quadruped_run 541/1.122, hopper_hop 261/1.704, reacher_hard 572 x 1.51)." in captions[0][0]
    assert "(quadruped_run 541/1.122, hopper_hop 261/1.8, reacher_hard 572 x 1.51)." in captions[1][0]
    assert "The paper's best K: 5 at action repeat 1, 3 at 2, 1 at 4." in captions[0][1]
    assert "The paper's best K: 5 at action repeat 1, 3 at 2, 3 at 4." in captions[1][1]


def test_the_claim_of_docs_extending_is_one_rule_for_the_runs_and_the_simulation():
    """docs/extending.md's "Add a claim" runs as written: its rule judges the runs as one draw (its check) and the
    power simulation's draws at once, each draw as it judges that draw alone."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "extending.md").read_text(encoding="utf-8")
    code = text.split("## Add a claim", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    namespace: dict = {}
    exec(compile(code, "docs/extending.md", "exec"), namespace)
    spec = namespace["SPEC"]
    ctx = _ctx(PaperData())
    with pytest.raises(cl.NotEnoughData, match="need >= 2 seeds that reached 1M frames for: quadruped_run/TACO"):
        spec.check(ctx)  # no runs
    rng = np.random.default_rng(0)
    draws = {(t, "TACO"): rng.normal(550.0, 50.0, size=(50, 3)) for t in DMC9}
    many = spec.simulation.judge(ctx, draws)
    assert set(many.verdicts) == {cl.SUPPORTED, cl.REFUTED}
    for i in range(50):
        one = spec.simulation.judge(ctx, {k: v[i:i + 1] for k, v in draws.items()})
        assert list(one.verdicts) == [many.verdicts[i]] and (i > 0 or one.evidence == many.evidence)
    claim = power.SimClaim(spec.id, power.load_budgets()["online_avg_gain"], spec.simulation.sources(ctx, 1e6),
                           spec.simulation.judge)
    assert 0.0 < power.simulate(ctx, claim, 6, 200).supported < 1.0  # Table 1's TACO: a 9-task mean of 560
