"""The README's main job: `repro reproduce` trains the tiny online grid (recorded), makes two datasets from one
of its runs, trains every offline learner on them, and builds the whole report from all of it (conftest's
session fixture ``main_job`` runs it once in the background, then a second time on the same folders)."""

import json

import pandas as pd
import pytest

from helpers import MAIN_JOB

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group(MAIN_JOB)]

OFFLINE = {"td3bc": "TD3+BC", "td3bc_taco": "TD3+BC+TACO", "cql": "CQL", "cql_taco": "CQL+TACO", "iql": "IQL",
           "bc": "BC", "dt": "DT"}


def test_tiny_end_to_end_reproduction_online(main_job):
    runs, out, stdout = main_job.runs, main_job.out, main_job.stdout
    done = sorted(runs.glob("tiny/*/*/*/*/DONE"))
    assert len(done) == 8
    assert all(json.loads(p.read_text())["frame"] == 400 for p in done)
    assert "eval.csv" in stdout and "episode_reward" in stdout  # the eval rows are printed
    for name in ("REPORT.md", "REPORT.html", "T1.csv", "T1.md", "T1.tex", "F4.png", "F4.pdf", "F11.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    t1 = pd.read_csv(out / "T1.csv")
    row = t1[(t1.task == "cheetah_run") & (t1.method == "TACO")].iloc[0]
    assert row.n == 2 and row.repro_mean == row.repro_mean  # reproduced from the two seeds (not NaN)
    assert t1[(t1.task == "quadruped_run") & (t1.method == "TACO")].iloc[0].n == 0  # no runs: shown, not faked
    # 400-frame runs of 100-frame episodes beside the paper's 1M frames: shown as what they are, never compared
    assert str(row.comparable) == "False" and row["diff"] != row["diff"] and row.paper_in_ci != row.paper_in_ci
    line = next(ln for ln in (out / "T1.md").read_text().splitlines() if ln.startswith("| Cheetah Run | TACO |"))
    assert "(400 frames, not comparable)" in line and "| n/a | n/a |" in line and "100-frame episodes" in line
    report = (out / "REPORT.md").read_text()
    assert "30 runs loaded (30 done)" in report and "## Claims" in report and "Audit" in report


def test_tiny_end_to_end_reproduction_offline(main_job):
    runs, out = main_job.runs, main_job.out
    for kind in ("medium", "full-replay"):
        manifest = json.loads((runs / "datasets" / "cheetah_run" / kind / "manifest.json").read_text())
        assert manifest["kind"] == kind and manifest["transitions"] > 0
    offline = sorted(runs.glob("tiny_offline/*/*/cheetah_run/*/seed_*/DONE"))
    assert len(offline) == 2 * (2 * 4 + 3)  # two datasets; two seeds of the four learners T3b pairs, one of three
    t3 = pd.read_csv(out / "T3.csv")
    for kind in ("medium", "full-replay"):
        for method in OFFLINE.values():
            cell = t3[(t3.task == "cheetah_run") & (t3.dataset == kind) & (t3.method == method)]
            seeds = 1 if method in ("IQL", "BC", "DT") else 2
            assert len(cell) == 1 and cell.iloc[0].n == seeds and cell.iloc[0].repro_mean == cell.iloc[0].repro_mean, \
                (kind, method)
    assert (t3[t3.n > 0].comparable.astype(str) == "False").all()  # 20 updates: below the paper's (100K on)
    t3b = pd.read_csv(out / "T3b.csv")
    pairs = t3b[(t3b.task == "cheetah_run") & t3b.dataset.isin(["medium", "full-replay"])]
    assert len(pairs) == 4 and pairs.poi.between(0, 1).all() and (pairs.n_method == 2).all(), pairs
    t6 = pd.read_csv(out / "T6.csv").set_index(["task", "dataset"])
    for kind, alpha in (("medium", 0.5), ("full-replay", 4.0)):  # Table 6, used by the CQL(+TACO) runs
        assert t6.loc[("cheetah_run", kind), "runs_alpha"] == alpha and t6.loc[("cheetah_run", kind), "runs"] == 4
    report = (out / "REPORT.md").read_text()
    verdicts = [ln for ln in report.splitlines() if ln.startswith("|")
                and {c.strip() for c in ln.split("|")} & {"supported", "refuted"}]  # a verdict cell, not a header
    assert not verdicts, verdicts  # tiny runs never give a verdict


def test_second_invocation_finds_everything_done(main_job):
    """Run again on the same folders (conftest runs it right after the first): every run is found done and
    none is touched (each DONE file keeps its modification time), and the report is rebuilt."""
    assert "8 already done" in main_job.again and "22 already done" in main_job.again, main_job.again[-3000:]
    assert main_job.done_before and main_job.done_after == main_job.done_before
    assert len(main_job.done_before) == 8 + 22
    assert "report: " in main_job.again and (main_job.out / "REPORT.md").is_file()


def test_the_report_html_is_one_file_that_shows_every_figure(main_job, tmp_path):
    """REPORT.html embeds every figure REPORT.md links (PNG data URIs); opened alone in headless Chromium, each
    loads, shows and is drawn in a screenshot read back (tests/browser.py; skipped where Chromium is not installed)."""
    import re

    from browser import check_report_html, image_sources

    page = main_job.out / "REPORT.html"
    linked = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", (main_job.out / "REPORT.md").read_text())
    sources = image_sources(page.read_text())
    assert len(linked) >= 10 and len(sources) == len(linked)
    assert all(s.startswith("data:image/png;base64,") for s in sources)
    check_report_html(page, tmp_path)
