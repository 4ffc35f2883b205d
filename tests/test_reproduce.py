"""The README's main job: `repro reproduce` trains the tiny grid and builds the whole report from it."""

import json
import subprocess
import sys

import pandas as pd
import pytest

pytestmark = pytest.mark.slow


def test_tiny_end_to_end_reproduction(tmp_path):
    runs, out = tmp_path / "runs", tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "repro", "reproduce", "--results", str(runs), "--out", str(out),
                           "--max-parallel", "2"], capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    done = sorted(runs.glob("tiny/*/*/*/*/DONE"))
    assert len(done) == 8
    assert all(json.loads(p.read_text())["frame"] == 400 for p in done)
    assert "eval.csv" in proc.stdout and "episode_reward" in proc.stdout  # the eval rows are printed
    for name in ("REPORT.md", "REPORT.html", "T1.csv", "T1.md", "T1.tex", "F4.png", "F4.pdf", "F11.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    t1 = pd.read_csv(out / "T1.csv")
    row = t1[(t1.task == "cheetah_run") & (t1.method == "TACO")].iloc[0]
    assert row.n == 2 and row.repro_mean == row.repro_mean  # reproduced from the two seeds (not NaN)
    assert t1[(t1.task == "quadruped_run") & (t1.method == "TACO")].iloc[0].n == 0  # no runs: shown, not faked
    report = (out / "REPORT.md").read_text()
    assert "8 runs loaded (8 done)" in report and "## Claims" in report and "Audit" in report
    # a second invocation finds everything done and only rebuilds the report
    again = subprocess.run([sys.executable, "-m", "repro", "reproduce", "--results", str(runs), "--out", str(out)],
                           capture_output=True, text=True, timeout=900)
    assert again.returncode == 0
    assert sorted(runs.glob("tiny/*/*/*/*/DONE")) == done
