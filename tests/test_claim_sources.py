"""Claims as specs (issue 36): each claim of claims.csv has exactly one spec (analysis.claims.SPECS), `repro claims`,
`repro plan --claims` and the report list the same claims, and the paper's printed numbers a claim compares with or
quotes are read from the packaged paper data (repro_data/paper/), not repeated as literals in analysis/claims.py."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import claims as cl
from analysis import power
from analysis.claim_budget import BUDGETS_CSV
from analysis.context import Context
from analysis.load import Results
from analysis.paper import PaperData


def _ctx(paper: PaperData) -> Context:
    return Context(results=Results(Path("."), pd.DataFrame(), pd.DataFrame()), paper=paper, reps=200)


def test_offline_average_reads_table_3s_printed_averages_from_the_paper_data(tmp_path):
    packaged = PaperData()
    avg = packaged.offline_average
    assert cl.offline_printed(_ctx(packaged)) == {
        m: float(avg.loc[avg["method"] == m, "average_normalized"].iloc[0]) for m in cl.OFFLINE_AVERAGED}
    # another copy of the paper data with other printed averages: the rule reads those
    root = tmp_path / "paper"
    shutil.copytree(packaged.root, root)
    edited = avg.assign(average_normalized=np.where(avg["method"] == "CQL", 10.0, avg["average_normalized"]))
    edited.to_csv(root / "offline_average.csv", index=False)
    ctx = _ctx(PaperData(root))
    assert cl.offline_printed(ctx)["CQL"] == 10.0
    # every method's runs at its printed average: inside the CI; CQL's printed value moved to 10: outside
    matrices = {m: np.full((3, 12), p) + np.linspace(-1, 1, 3)[:, None]
                for m, p in cl.offline_printed(_ctx(packaged)).items()}
    verdict, evidence = cl.offline_average_rule(ctx, matrices)
    assert verdict == cl.REFUTED and "vs 10.0 (outside)" in evidence
    assert cl.offline_average_rule(_ctx(packaged), matrices)[0] == cl.SUPPORTED


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
    table = {}
    for t in cl.REPR_TASKS:
        table[(t, "TACO")] = (3, 500.0)
        for m in packaged.repr_others:
            table[(t, m)] = (3, 600.0 if m == "ATC" else 400.0)
    assert cl.vs_repr_rule(_ctx(packaged), table)[0] == cl.REFUTED
    assert cl.vs_repr_rule(_ctx(without_atc), table)[0] == cl.SUPPORTED


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
    assert judged == ids  # each claim of claims.csv once, in its order
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
    x, y = np.full((3, 9), 500.0), np.full((3, 9), 400.0)
    assert "Table 1 gives 1.397)" in cl.avg_gain_rule(_ctx(paper), x, y)[1]
    doubled = PaperData()
    online = doubled.online
    doubled.__dict__["online"] = online.assign(mean=np.where(online["method"] == "TACO", 2 * online["mean"],
                                                             online["mean"]))
    assert "Table 1 gives 2.794)" in cl.avg_gain_rule(_ctx(doubled), x, y)[1]
