"""Offline training: BC loss, dataset -> replay loading and sampling, bad datasets, and tiny end-to-end BC runs
(real environment for evaluation) with SIGKILL + resume."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

from helpers import kill_when, rows
from offline_fixtures import action_of, reward_of, write_dataset
from repro.config.compose import compose, typed  # noqa: E402
from repro.data.offline_replay import DatasetError, load_offline_data  # noqa: E402
from repro.data.reference import PAPER_TACO_RETURN, normalized_score, score_reference  # noqa: E402
from repro.learners import LEARNERS, Learner, build_learner  # noqa: E402
from repro.learners.bc import bc_loss  # noqa: E402
from repro.runs import rundir  # noqa: E402
from repro.runs.runformat import OFFLINE_EVAL_COLUMNS, OFFLINE_WALLCLOCK_COLUMNS  # noqa: E402
from repro.train import api  # noqa: E402
from repro_app.cli import app  # noqa: E402

# its module-scoped runs are made once: every test of this module on one pytest-xdist worker
pytestmark = pytest.mark.xdist_group("offline_train")

TINY = ["agent=bc", "task=cheetah_run", "profile=tiny", "seed=2", "runtime.threads=1", "offline.dataset=medium",
        "offline.updates=20", "offline.eval_every_updates=10", "offline.eval_episodes=1",
        "offline.checkpoint_every_updates=5", "offline.log_every_updates=5"]
REL = Path("default/bc/base/cheetah_run/medium/seed_2")


# ----------------------------------------------------------------------------- BC loss and learner
def test_bc_loss_known_answer_and_gradient():
    pred = torch.tensor([[0.5, -1.0], [0.0, 1.0]], dtype=torch.float64, requires_grad=True)
    target = torch.tensor([[0.0, 0.0], [1.0, 1.0]], dtype=torch.float64)
    loss = bc_loss(pred, target)
    assert loss.item() == pytest.approx((0.25 + 1.0 + 1.0 + 0.0) / 4, abs=1e-15)
    loss.backward()
    assert torch.allclose(pred.grad, 2 * (pred - target).detach() / 4)
    with pytest.raises(ValueError):
        bc_loss(pred, target[:, :1])


def _bc(**over) -> Learner:
    rc = typed(compose(["agent=bc", "profile=tiny", "task=hopper_hop"] + [f"{k}={v}" for k, v in over.items()]))
    torch.manual_seed(0)
    return build_learner(rc.agent, (9, 32, 32), 4, "cpu")


def test_bc_update_trains_encoder_and_actor_on_the_dataset_action():
    learner = _bc()
    assert isinstance(learner, Learner) and LEARNERS["bc"] is type(learner)
    assert [n for n, _ in learner.parameter_counts()] == ["encoder", "actor"]
    gen = torch.Generator().manual_seed(1)
    batch = {"obs": torch.randint(0, 256, (8, 9, 32, 32), generator=gen, dtype=torch.uint8),
             "action": torch.rand(8, 4, generator=gen) * 1.6 - 0.8}
    before = {k: v.clone() for k, v in learner.encoder.state_dict().items()}
    first = learner.update(batch, 0)["bc_loss"]
    assert any(not torch.equal(before[k], v) for k, v in learner.encoder.state_dict().items())
    for step in range(1, 25):
        last = learner.update(batch, step)["bc_loss"]
    assert last < 0.7 * first
    obs = batch["obs"][0].numpy()
    a = learner.act(obs, 0, eval_mode=True)
    assert a.shape == (4,) and np.array_equal(a, learner.act(obs, 0, eval_mode=False))  # deterministic policy


# ----------------------------------------------------------------------------- dataset -> replay
def _load(directory: Path, **kw):
    args = dict(task="hopper_hop", action_dim=4, frame_shape=(3, 84, 84), frame_stack=3, nstep=3, K=2,
                discount=0.9, seed=0)
    args.update(kw)
    return load_offline_data(directory, **args)


def test_replay_samples_stacks_nstep_and_action_sequences_within_episodes(tmp_path: Path):
    lengths = (12, 9, 15)
    data = _load(write_dataset(tmp_path / "d", lengths=lengths, frame_shape=(3, 8, 8)), frame_shape=(3, 8, 8))
    batch = data.buffer.sample(2000)
    seen = set()
    for i in range(2000):
        obs = batch["obs"][i].numpy().reshape(3, 3, 8, 8)  # oldest first
        ep, t = int(obs[-1, 0, 0, 0]), int(obs[-1, 0, 0, 1])
        seen.add((ep, t))
        assert t + 3 <= lengths[ep]
        assert [int(obs[j, 0, 0, 1]) for j in range(3)] == [max(t - 2, 0), max(t - 1, 0), t]
        assert {int(obs[j, 0, 0, 0]) for j in range(3)} == {ep}
        nxt = batch["next_obs"][i].numpy().reshape(3, 3, 8, 8)
        assert (int(nxt[-1, 0, 0, 0]), int(nxt[-1, 0, 0, 1])) == (ep, t + 3)
        fut = batch["future_obs"][i].numpy().reshape(3, 3, 8, 8)
        assert int(fut[-1, 0, 0, 1]) == t + 2
        assert np.array_equal(batch["action"][i].numpy(), action_of(ep, t, 4))
        assert np.array_equal(batch["action_seq"][i].numpy(), np.stack([action_of(ep, t + k, 4) for k in range(2)]))
        want = sum(0.9 ** k * reward_of(ep, t + k) for k in range(3))
        assert batch["reward"][i].item() == pytest.approx(want, rel=1e-6)
        assert batch["discount"][i].item() == pytest.approx(0.9 ** 3, rel=1e-6)
    assert seen == {(e, t) for e, n in enumerate(lengths) for t in range(n - 2)}


def test_replay_memory_within_ten_percent_of_raw_frames(tmp_path: Path):
    data = _load(write_dataset(tmp_path / "d", lengths=(30, 25, 20)))
    assert data.raw_frame_bytes == (30 + 25 + 20 + 3) * 3 * 84 * 84
    assert data.buffer.frame_bytes() == data.raw_frame_bytes
    assert data.buffer.nbytes() <= 1.10 * data.raw_frame_bytes


def test_bad_datasets_raise_one_line(tmp_path: Path):
    good = write_dataset(tmp_path / "good")
    cases = {"task": dict(task="walker_run"), "action": dict(action_dim=6), "size": dict(frame_shape=(3, 64, 64))}
    for name, kw in cases.items():
        with pytest.raises(DatasetError) as err:
            _load(good, **kw)
        assert "\n" not in str(err.value), name
    with pytest.raises(DatasetError, match="no dataset at"):
        _load(tmp_path / "nothing")
    bad = write_dataset(tmp_path / "truncated")
    f = bad / "episodes" / "ep_0000001.npz"
    f.write_bytes(f.read_bytes()[:100])
    with pytest.raises(DatasetError, match="episode"):
        _load(bad)
    short = write_dataset(tmp_path / "short", lengths=(2, 1))
    with pytest.raises(DatasetError, match="steps"):
        _load(short)


def test_score_reference_prefers_source_then_paper():
    assert score_reference("hopper_hop", {"best_return": 300.0}) == (300.0, "source")
    assert score_reference("hopper_hop", {"run_dir": "x"}) == (261.0, "paper")
    assert score_reference("hopper_hop", {"best_return": float("nan")}) == (261.0, "paper")
    assert score_reference("hammer", None) == (None, "none")
    assert normalized_score(50.0, 200.0) == 25.0 and normalized_score(50.0, None) is None


def test_packaged_paper_references_equal_table_1():
    """The TACO column of Table 1 as the paper's LaTeX prints it (tab:online_table), and the analysis reads the
    same packaged file."""
    from analysis.paper import PaperData

    printed = {"quadruped_run": 541, "hopper_hop": 261, "walker_run": 637, "quadruped_walk": 793, "cheetah_run": 821,
               "finger_turn_hard": 632, "acrobot_swingup": 241, "reacher_hard": 883, "reach_duplo": 234}
    assert PAPER_TACO_RETURN == {k: float(v) for k, v in printed.items()}
    taco = PaperData().online.query("method == 'TACO'")
    assert dict(zip(taco["task"], taco["mean"].astype(float))) == PAPER_TACO_RETURN


# ----------------------------------------------------------------------------- config, run dir, CLI
def test_run_dirs_online_unchanged_offline_by_dataset(tmp_path: Path):
    online = compose(["task=cheetah_run", "seed=3"])
    assert rundir.run_dir(online) == Path("runs/default/taco/base/cheetah_run/seed_3")
    assert rundir.run_dir(compose(TINY)) == Path("runs") / REL
    a = rundir.run_dir(compose(TINY[:-6] + ["offline.dataset=/data/a/medium"]))
    b = rundir.run_dir(compose(TINY[:-6] + ["offline.dataset=/data/b/medium"]))
    assert a.parent.name.startswith("medium-") and a != b


def test_dry_run_without_dataset_on_disk(tmp_path: Path):
    out = CliRunner().invoke(app, ["train", *TINY, f"runtime.results_root={tmp_path}", "--dry-run"])
    assert out.exit_code == 0, out.output
    assert "│ encoder" in out.output and "│ actor" in out.output and "│ critic" not in out.output
    assert str(tmp_path / REL) in out.output.replace("\n", "")
    assert not (tmp_path / "default").exists()


@pytest.mark.parametrize("extra, needle", [([], "unknown dataset"), (["task=walker_run"], "walker_run"),
                                           (["offline.dataset=null"], "offline.dataset")])
def test_cli_bad_dataset_one_line_exit_2_nothing_written(tmp_path: Path, extra: list[str], needle: str):
    write_dataset(tmp_path / "elsewhere" / "medium", task="cheetah_run", action_dim=6)  # not under datasets/
    if extra == ["task=walker_run"]:
        write_dataset(tmp_path / "datasets" / "walker_run" / "medium")  # a hopper_hop dataset in walker's place
    out = CliRunner().invoke(app, ["train", *TINY, *extra, f"runtime.results_root={tmp_path}", "--no-progress"])
    assert out.exit_code == 2
    lines = [ln for ln in out.output.strip().splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0], out.output
    assert not (tmp_path / "default").exists()


# ----------------------------------------------------------------------------- end to end (real env eval)
def _deterministic(csv: Path) -> pd.DataFrame:
    df = pd.read_csv(csv)
    return df.drop(columns=[c for c in OFFLINE_WALLCLOCK_COLUMNS if c in df.columns])


def _root_with_dataset(root: Path) -> Path:
    write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6, best_return=200.0)
    return root


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    root = _root_with_dataset(tmp_path_factory.mktemp("ref"))
    return api.train(TINY + [f"runtime.results_root={root}"], echo=lambda s: None)


@pytest.mark.slow
def test_bc_end_to_end_run_files_and_normalised_scores(reference: Path):
    for name in ("config.yaml", "meta.json", "eval.csv", "train.csv", "checkpoint.pt", "DONE"):
        assert (reference / name).is_file(), name
    ev = pd.read_csv(reference / "eval.csv")
    assert list(ev.columns) == OFFLINE_EVAL_COLUMNS
    assert list(ev["update"]) == [0, 10, 20] and (ev["eval_episodes"] == 1).all()
    assert (ev["score_reference"] == "source").all() and (ev["reference_return"] == 200.0).all()
    assert ev["episode_reward"].abs().min() > 0  # cheetah_run: a dense reward, so the score below can fail
    assert np.allclose(ev["normalized_score"], 100 * ev["episode_reward"] / 200.0)
    assert (ev["episode_length"] == 100).all()  # 50 agent steps x action repeat 2 (profile=tiny)
    tr = pd.read_csv(reference / "train.csv")
    assert list(tr["update"]) == [5, 10, 15, 20] and tr["bc_loss"].notna().all()
    ckpt = torch.load(reference / "checkpoint.pt", weights_only=True)
    assert ckpt["offline"]["update"] == 20 and set(ckpt["agent"]) == {"encoder", "actor"}
    assert json.loads((reference / "DONE").read_text())["update"] == 20
    resolved = json.loads((reference / "resolved.json").read_text())  # what analysis reads, from the run itself
    assert (resolved["learner"], resolved["dataset"], resolved["dataset_kind"]) == ("bc", "medium", "medium")
    assert resolved["dataset_manifest_sha256"] == hashlib.sha256(
        (Path(resolved["dataset_dir"]) / "manifest.json").read_bytes()).hexdigest()


@pytest.mark.slow
def test_offline_sigkill_and_resume_matches_uninterrupted_run(reference: Path, tmp_path: Path):
    root = _root_with_dataset(tmp_path)
    run = root / REL
    cmd = [sys.executable, "-m", "repro", "train", *TINY, f"runtime.results_root={root}", "--no-progress"]
    kill_when(cmd, lambda: rows(run / "eval.csv") >= 2, poll=0.01)  # after checkpoints at 5 and 10, mid-run
    assert (run / "checkpoint.pt").exists() and not (run / "DONE").exists()
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "resumed" in out.stdout and "at update 10" in out.stdout
    for name in ("eval.csv", "train.csv"):
        pd.testing.assert_frame_equal(_deterministic(run / name), _deterministic(reference / name))


def test_resume_refused_when_the_dataset_changed(tmp_path: Path):
    from types import SimpleNamespace

    from repro.train.offline_loop import OfflineLogger, OfflineLoop

    data = _load(write_dataset(tmp_path / "d", frame_shape=(3, 32, 32)), frame_shape=(3, 32, 32))
    env = SimpleNamespace(spec=SimpleNamespace(has_success=False))
    cfg = typed(compose(TINY)).offline
    (tmp_path / "run").mkdir()
    logger = OfflineLogger(tmp_path / "run", ["bc_loss"], echo=lambda s: None)
    loop = OfflineLoop(cfg, 1, 2, env, _bc(), data.buffer, logger, lambda s: None, (None, "none"), data.digest)
    state = loop.checkpoint_state()
    other = OfflineLoop(cfg, 1, 2, env, _bc(), data.buffer, logger, lambda s: None, (None, "none"), "f" * 64)
    with pytest.raises(DatasetError, match="dataset changed"):
        other.restore(state)
    loop.restore(state)  # the same dataset resumes
    logger.close()
