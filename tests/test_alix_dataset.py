"""A-LIX runs as dataset sources and A-LIX's per-task batch (issue 49).

* `repro dataset make` builds a snapshot's encoder and actor as the run's learner builds them (A-LIX's encoder holds
  its mixing strength) and acts in eval mode, without mixing, as the run acted.
* A-LIX's batch follows its authors' task files: 512 on walker, ``ALIX.yaml``'s 256 elsewhere (docs/deviations.md).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from helpers import TINY_ALIX
from repro.config.compose import compose, typed
from repro.config.schema import RunConfig
from repro.data.record import PolicySpec, Recorder, load_snapshot, snapshot_path
from repro.train import make_dataset as mk
from repro.train.common import episode_seed

OBS, ACTIONS = (9, 84, 84), 6


def _alix(*overrides: str) -> RunConfig:
    return typed(compose(["agent=alix", "profile=tiny", *overrides]))


def _alix_snapshot(tmp_path: Path, strength: float) -> tuple[RunConfig, Path, torch.nn.Module]:
    """A snapshot of a freshly built tiny A-LIX learner whose strength is ``strength``; its config, path and the
    learner's encoder."""
    from repro.learners import build_learner

    rc = _alix()
    learner = build_learner(rc.agent, OBS, ACTIONS, "cpu")
    encoder = learner.backbone.encoder  # type: ignore[attr-defined]
    with torch.no_grad():
        encoder.strength.fill_(strength)
    rec = Recorder(tmp_path, PolicySpec(OBS, ACTIONS, rc.agent.feature_dim, rc.agent.hidden_dim))
    rec.snapshot(learner, step=10, frame=20, eval_return=1.0)  # type: ignore[arg-type]
    return rc, snapshot_path(rec.snapshots, 10), encoder


def test_an_alix_snapshot_loads_into_the_alix_encoder_and_acts_without_mixing(tmp_path: Path):
    from repro.agent.alix import ALIXEncoder

    rc, path, trained = _alix_snapshot(tmp_path, 0.7)
    state = load_snapshot(path)
    assert "strength" in state["encoder"]
    encoder, actor = mk.snapshot_policy(rc, path, state, "cpu")
    assert isinstance(encoder, ALIXEncoder) and not encoder.training and not actor.training
    assert float(encoder.strength.detach()) == pytest.approx(0.7)
    for k, v in trained.state_dict().items():
        assert torch.equal(encoder.state_dict()[k], v)
    obs = torch.randint(0, 256, (2, *OBS)).float()
    with torch.no_grad():
        assert torch.equal(encoder(obs), encoder(obs))  # eval mode: no random shift of the feature maps
        trained.train(True)
        assert not torch.equal(trained(obs), encoder(obs))  # training mode mixes (strength 0.7)


def test_a_snapshot_that_does_not_fit_the_run_s_learner_is_one_line(tmp_path: Path):
    _, path, _ = _alix_snapshot(tmp_path, 0.5)
    taco = typed(compose(["agent=taco", "profile=tiny"]))
    with pytest.raises(mk.MakeError) as err:
        mk.snapshot_policy(taco, path, load_snapshot(path), "cpu")
    message = str(err.value)
    assert "\n" not in message and "encoder does not fit" in message and "strength" in message


def test_alix_batch_follows_its_authors_task_files():
    assert _batch("agent=alix", "task=walker_run") == (512, 1)  # cfgs/task/walker_run.yaml: batch 512, nstep 1
    assert _batch("agent=alix", "task=cheetah_run") == (256, 3)  # ALIX.yaml: batch 256, nstep 3
    assert _batch("agent=alix", "task=quadruped_run") == (256, 3)
    assert _batch("agent=alix", "task=walker_run", "agent.batch_size=256") == (256, 1)
    assert _batch("agent=alix", "task=walker_run", "profile=tiny") == (8, 1)  # a profile still sets it
    assert _batch("agent=taco", "task=walker_run") == (1024, 1)  # TACO and DrQ-v2 on walker unchanged
    assert _batch("agent=drqv2", "task=walker_run") == (512, 1)


def _batch(*overrides: str) -> tuple[int, int]:
    agent = typed(compose(list(overrides))).agent
    return agent.batch_size, agent.nstep


def _repro(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "repro", *args], capture_output=True, text=True, timeout=900)


@pytest.mark.slow
@pytest.mark.xdist_group(TINY_ALIX)
def test_a_medium_dataset_is_made_from_a_recorded_tiny_alix_run_with_the_cli(tiny_alix: Path, tmp_path: Path):
    run = tiny_alix  # a recorded tiny A-LIX run through a sweep (conftest), also read by test_alix_train
    dataset = tmp_path / "datasets" / "cheetah_run" / "medium"
    made = _repro("dataset", "make", "--source", str(run), "--kind", "medium", "--transitions", "60", "--out",
                  str(dataset))
    assert made.returncode == 0, made.stderr
    checked = _repro("dataset", "check", str(dataset))
    assert checked.returncode == 0 and checked.stdout.startswith("ok:"), checked.stdout + checked.stderr
    manifest = mk.manifest_json(dataset)
    assert manifest["source"]["agent"] == "alix" and manifest["transitions"] == 100  # two whole 50-step episodes
    _first_action_is_the_eval_mode_policy_s(run, dataset, manifest)


def _first_action_is_the_eval_mode_policy_s(run: Path, dataset: Path, manifest: dict) -> None:
    """The dataset's first action is the snapshot's A-LIX policy (eval mode, no mixing) plus the rollout's noise."""
    source = mk.open_source(run)
    snap_path = run / "record" / "snapshots" / f"step_{manifest['source']['snapshot_step']:09d}.pt"
    state = load_snapshot(snap_path)
    encoder, actor = mk.snapshot_policy(source.cfg, snap_path, state, "cpu")
    std = float(state["stddev"])
    with np.load(dataset / manifest["episodes"][0]["file"]) as z:
        frames, first = z["frames"], z["actions"][0]
    obs = torch.as_tensor(np.concatenate([frames[0]] * 3)).float().unsqueeze(0)
    noise = torch.Generator().manual_seed(episode_seed(source.cfg.seed, mk.ROLLOUT_KIND + 1, 0, 0))
    with torch.no_grad():
        dist = actor(encoder(obs), std)
        eps = torch.randn(dist.loc.shape, generator=noise) * std
        action = torch.clamp(dist.loc + eps, dist.low + dist.eps, dist.high - dist.eps)
    np.testing.assert_allclose(first, action.numpy()[0], atol=1e-6)
