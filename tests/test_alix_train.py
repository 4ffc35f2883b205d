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
from typer.testing import CliRunner

from helpers import deterministic, kill_when, launch_app, rows
from repro.runs import rundir
from repro.runs.runformat import CHECKPOINT, DONE, EVAL, TRAIN

pytestmark = pytest.mark.slow

# the tiny profile's 4 episodes of 100 frames (evaluations at 0, 200, 400); updates from frame 40 on, so the first
# checkpoint (after episode 1) holds updated networks, a moved strength and the encoder optimizer's two groups
TINY_ALIX = ["profile=tiny", "runtime.threads=1", "train.seed_frames=40", "train.explore_steps=10",
             "train.save_frames=false"]
REL = Path("alix_tiny/alix/base/cheetah_run/seed_1")


def test_a_tiny_alix_run_through_a_sweep_and_a_killed_and_resumed_train_give_the_same_logs(tmp_path: Path):
    sweep = tmp_path / "alix_tiny.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "alix_tiny", "description": "a tiny A-LIX run", "artifacts": [], "experiment": "alix_tiny",
        "tasks": ["cheetah_run"], "agents": ["alix"], "seeds": 1, "frames": None,
        "eval": {"every_frames": None, "episodes": None}, "common": TINY_ALIX, "variants": {"base": []}}))
    swept = tmp_path / "swept"
    out = CliRunner().invoke(launch_app(), ["sweep", str(sweep), "--results-root", str(swept)])
    assert out.exit_code == 0, out.output
    reference = swept / REL
    assert (reference / DONE).is_file()
    cfg = yaml.safe_load((reference / rundir.CONFIG).read_text())
    assert cfg["agent"]["learner"] == "alix" and cfg["agent"]["alix"]["target"] == 0.535
    train = pd.read_csv(reference / TRAIN)
    strength = train["lix_strength"].dropna()
    assert len(strength) == len(train) == 4 and strength.between(0, 1).all() and (strength != 0.5).all()
    ckpt = torch.load(reference / CHECKPOINT, weights_only=True)
    assert "strength" in ckpt["agent"]["encoder"] and len(ckpt["optimizers"]["encoder"]["param_groups"]) == 2

    root = tmp_path / "trained"
    run = root / REL
    cmd = [sys.executable, "-m", "repro", "train", "agent=alix", "task=cheetah_run", "seed=1", "experiment=alix_tiny",
           *TINY_ALIX, f"runtime.results_root={root}", "--no-progress"]
    kill_when(cmd, lambda: (run / CHECKPOINT).exists() and rows(run / TRAIN) >= 1, timeout=900)
    assert not (run / DONE).exists()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "resumed" in done.stdout
    for name in (EVAL, TRAIN):
        pd.testing.assert_frame_equal(deterministic(run / name), deterministic(reference / name))
