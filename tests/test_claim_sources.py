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
