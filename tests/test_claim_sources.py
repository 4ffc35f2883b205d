"""The paper's printed numbers a claim compares with are read from the packaged paper data (repro_data/paper/), not
repeated as literals in analysis/claims.py (issue 36)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from analysis import claims as cl
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
