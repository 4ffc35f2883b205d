"""End-to-end runs with real rendering and real updates: run directory, determinism, SIGKILL and resume."""

import json
import os
import platform
import signal
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import pandas as pd
import pytest
import torch
import yaml

from repro import api, rundir
from repro.logger import WALLCLOCK_COLUMNS

pytestmark = pytest.mark.slow

TINY = ["profile=tiny", "task=cheetah_run", "seed=3", "runtime.threads=1"]
REL = Path("default/taco/base/cheetah_run/seed_3")


def deterministic(csv: Path) -> pd.DataFrame:
    df = pd.read_csv(csv)
    return df.drop(columns=[c for c in WALLCLOCK_COLUMNS if c in df.columns])


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ref")
    return api.train(TINY + [f"runtime.results_root={root}"], echo=lambda s: None)


def test_run_directory_contract(reference: Path):
    for name in ("config.yaml", "meta.json", "eval.csv", "train.csv", "checkpoint.pt", "DONE"):
        assert (reference / name).is_file(), name
    cfg = yaml.safe_load((reference / "config.yaml").read_text())
    assert cfg["agent"]["name"] == "taco" and cfg["task"]["name"] == "cheetah_run" and cfg["seed"] == 3
    meta = json.loads((reference / "meta.json").read_text())
    for key in ("git_sha", "git_dirty", "versions", "host", "device", "command"):
        assert key in meta
    assert meta["versions"]["torch"] == metadata.version("torch") == torch.__version__
    assert meta["versions"]["python"] == platform.python_version()
    assert meta["host"] == socket.gethostname() and meta["resumes"] == []
    assert meta["device"] == rundir.device_name(api.resolve_device("auto"))
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(api.__file__).parent, capture_output=True,
                          text=True, check=False)
    if head.returncode == 0:  # a git checkout: the run names the commit it was trained from
        assert meta["git_sha"] == head.stdout.strip() and isinstance(meta["git_dirty"], bool)
    ev = pd.read_csv(reference / "eval.csv")
    assert list(ev["frame"]) == [0, 200, 400]
    assert list(ev["step"]) == [0, 100, 200]
    assert ev["success"].isna().all()  # DMC has no success signal
    tr = pd.read_csv(reference / "train.csv")
    assert list(tr["episode"]) == [1, 2, 3, 4] and list(tr["frame"]) == [100, 200, 300, 400]
    assert tr["taco_loss"].iloc[1:].notna().all() and tr["critic_loss"].iloc[1:].notna().all()
    ckpt = torch.load(reference / "checkpoint.pt", weights_only=True)
    assert "action_encoder" in ckpt["agent"] and "step.0.weight" in ckpt["agent"]["action_encoder"]
    import numpy as np

    frames = np.load(reference / "frames.npz")["frames"]
    assert frames.shape == (51, 84, 84, 3) and frames.dtype == np.uint8 and frames.std() > 0
    done = json.loads((reference / "DONE").read_text())
    assert done["frame"] == 400


def test_same_seed_same_config_gives_identical_logs(reference: Path, tmp_path: Path):
    run = api.train(TINY + [f"runtime.results_root={tmp_path}"], echo=lambda s: None)
    for name in ("eval.csv", "train.csv"):
        pd.testing.assert_frame_equal(deterministic(run / name), deterministic(reference / name))


def _rows(csv: Path) -> int:
    return max(len(csv.read_text().splitlines()) - 1, 0) if csv.exists() else 0


def _train_cmd(root: Path) -> list[str]:
    return [sys.executable, "-m", "repro", "train", *TINY, f"runtime.results_root={root}", "--no-progress"]


def _kill_when(cmd: list[str], ready, timeout: float = 300) -> None:
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ.copy())
    t0 = time.time()
    while not ready() and proc.poll() is None and time.time() - t0 < timeout:
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()


def test_sigkill_and_resume_matches_uninterrupted_run(reference: Path, tmp_path: Path):
    run = tmp_path / REL
    # 1st kill: right after the first evaluation row, before any checkpoint exists
    _kill_when(_train_cmd(tmp_path), lambda: _rows(run / "eval.csv") >= 1)
    assert not (run / "DONE").exists()
    early_checkpoint = (run / "checkpoint.pt").exists()  # the kill is meant to come first; if not, one more resume
    # 2nd kill: after a checkpoint, in the middle of a later episode
    _kill_when(_train_cmd(tmp_path), lambda: _rows(run / "train.csv") >= 2 and (run / "checkpoint.pt").exists()
               and _rows(run / "eval.csv") >= 2)
    assert not (run / "DONE").exists()
    out = subprocess.run(_train_cmd(tmp_path), capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "resumed" in out.stdout
    for name in ("eval.csv", "train.csv"):
        pd.testing.assert_frame_equal(deterministic(run / name), deterministic(reference / name))
    meta = json.loads((run / "meta.json").read_text())
    assert len(meta["resumes"]) == 1 + early_checkpoint  # a start without a checkpoint is no resume


def test_rerun_of_done_run_is_skipped_and_other_config_refused(reference: Path):
    root = reference.parents[4]
    before = (reference / "eval.csv").read_bytes()
    out = subprocess.run([sys.executable, "-m", "repro", "train", *TINY, f"runtime.results_root={root}"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "already done" in out.stdout
    out = subprocess.run([sys.executable, "-m", "repro", "train", *TINY, "agent.K=1",
                          f"runtime.results_root={root}"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "another config" in lines[0] and "agent.K" in lines[0]
    assert (reference / "eval.csv").read_bytes() == before
