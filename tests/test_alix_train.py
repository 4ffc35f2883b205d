"""A tiny A-LIX run (issue 38) through `repro sweep`, and the same run through `repro train`, killed after its first
checkpoint and resumed: the resumed run's logs are the uninterrupted one's (as tests/test_train_e2e.py checks for
TACO)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import torch
import yaml

from helpers import TINY_ALIX, TINY_ALIX_REL, TINY_ALIX_SETS, deterministic, kill_when, rows
from repro.runs import rundir
from repro.runs.runformat import CHECKPOINT, DONE, EVAL, TRAIN

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group(TINY_ALIX)]


def test_a_tiny_alix_run_through_a_sweep_and_a_killed_and_resumed_train_give_the_same_logs(tiny_alix: Path,
                                                                                              tmp_path: Path):
    reference = tiny_alix  # the sweep's run (conftest)
    assert (reference / DONE).is_file()
    cfg = yaml.safe_load((reference / rundir.CONFIG).read_text())
    assert cfg["agent"]["learner"] == "alix" and cfg["agent"]["alix"]["target"] == 0.535
    train = pd.read_csv(reference / TRAIN)
    strength = train["lix_strength"].dropna()
    assert len(strength) == len(train) == 4 and strength.between(0, 1).all() and (strength != 0.5).all()
    ckpt = torch.load(reference / CHECKPOINT, weights_only=True)
    assert "strength" in ckpt["agent"]["encoder"] and len(ckpt["optimizers"]["encoder"]["param_groups"]) == 2

    root = tmp_path / "trained"
    run = root / TINY_ALIX_REL
    cmd = [sys.executable, "-m", "repro", "train", "agent=alix", "task=cheetah_run", "seed=1", "experiment=alix_tiny",
           *TINY_ALIX_SETS, f"runtime.results_root={root}", "--no-progress"]
    kill_when(cmd, lambda: (run / CHECKPOINT).exists() and rows(run / TRAIN) >= 1, timeout=900)
    assert not (run / DONE).exists()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "resumed" in done.stdout
    for name in (EVAL, TRAIN):
        pd.testing.assert_frame_equal(deterministic(run / name), deterministic(reference / name))
