"""Known-answer and gradient-flow tests of the agent core and the TACO / CURL / reward objectives."""

import math

import numpy as np
import pytest
import torch

from helpers import OBS, make_batch
from repro.agent.agent import Agent
from repro.agent.aug import RandomShift
from repro.agent.networks import SharedHeads, default_latent_action_dim
from repro.agent.objectives import AuxBatch, ObjectiveContext
from repro.agent.objectives.base import info_nce
from repro.agent.objectives.taco import CURLObjective, RewardObjective, TACOObjective
from repro.config.compose import compose, typed


def agent_for(overrides, A=4):
    torch.manual_seed(0)
    rc = typed(compose(["agent.hidden_dim=32"] + overrides))
    return Agent(rc.agent, OBS, A)


def test_info_nce_known_answer():
    logits = torch.tensor([[2.0, 0.0], [0.0, 2.0]])
    loss, acc = info_nce(logits)
    assert loss.item() == pytest.approx(math.log(1 + math.exp(-2.0)), rel=1e-6)
    assert acc == 1.0
    loss, acc = info_nce(torch.tensor([[0.0, 1.0], [0.0, 1.0]]))
    assert loss.item() == pytest.approx(0.5 * (math.log(1 + math.e) - 0.0) + 0.5 * math.log(1 + math.exp(-1)),
                                        rel=1e-6)
    assert acc == 0.5


def test_bilinear_logits_subtract_row_max():
    heads = SharedHeads(repr_dim=8, feature_dim=2)
    with torch.no_grad():
        heads.W.copy_(torch.tensor([[1.0, 0.0], [0.0, 2.0]]))
    x = torch.tensor([[1.0, 1.0], [2.0, 0.0]])
    y = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    raw = np.array([[1.0, 2.0], [2.0, 0.0]])  # x W y^T by hand
    expected = raw - raw.max(axis=1, keepdims=True)
    np.testing.assert_allclose(heads.logits(x, y).detach().numpy(), expected)


def infonce64(x: torch.Tensor, W: torch.Tensor, y: torch.Tensor) -> tuple[float, float]:
    """InfoNCE over s = x W y^T against the diagonal, by hand in float64: (loss, accuracy)."""
    x, W, y = (t.detach().numpy().astype(np.float64) for t in (x, W, y))
    s = x @ W @ y.T
    m = s.max(1, keepdims=True)
    log_softmax_diag = np.diag(s) - (np.log(np.exp(s - m).sum(1)) + m[:, 0])
    return float(-log_softmax_diag.mean()), float((s.argmax(1) == np.arange(len(s))).mean())


def _ctx(K=3, A=4, d_u=6):
    return ObjectiveContext(repr_dim=32 * 35 * 35, feature_dim=50, hidden_dim=32, action_dim=A, K=K, seq_dim=K * d_u)


def test_taco_loss_matches_formula():
    torch.manual_seed(0)
    from repro.agent.networks import ActionEncoder, Encoder

    ctx = _ctx()
    enc, act = Encoder(OBS), ActionEncoder(4, 6, 3)
    taco = TACOObjective(ctx)
    batch = make_batch()
    aux = AuxBatch(batch, enc, RandomShift(), act.encode_sequence, "nstep")
    loss, metrics = taco(aux)
    # recompute by the paper's formula from the same views
    z = ctx.shared().state_proj(aux.anchor())
    g = taco.proj_sa(torch.cat([z, aux.action_sequence()], -1))
    h = ctx.shared().state_proj(aux.future())
    expected, acc = infonce64(g, ctx.shared().W, h)
    assert loss.item() == pytest.approx(expected, rel=1e-4)
    assert metrics["taco_loss"] == pytest.approx(loss.item()) and metrics["taco_acc"] == pytest.approx(acc)


def test_reward_loss_targets():
    torch.manual_seed(0)
    from repro.agent.networks import ActionEncoder, Encoder

    ctx = _ctx()
    head = RewardObjective(ctx)
    with torch.no_grad():  # make the prediction a constant 0.5
        head.head[-1].weight.zero_()
        head.head[-1].bias.fill_(0.5)
    batch = make_batch()
    enc, act = Encoder(OBS), ActionEncoder(4, 6, 3)
    for target, key in (("nstep", "reward"), ("ksum", "reward_ksum")):
        aux = AuxBatch(batch, enc, RandomShift(), act.encode_sequence, target)
        loss, _ = head(aux)
        expected = ((0.5 - batch[key].numpy()) ** 2).mean()
        assert loss.item() == pytest.approx(float(expected), rel=1e-5)


def test_curl_positive_is_other_augmentation_without_gradient():
    torch.manual_seed(0)
    from repro.agent.networks import ActionEncoder, Encoder

    ctx = _ctx()
    curl = CURLObjective(ctx)
    enc, act = Encoder(OBS), ActionEncoder(4, 6, 3)
    aux = AuxBatch(make_batch(), enc, RandomShift(), act.encode_sequence, "nstep")
    loss, m = curl(aux)
    assert aux.positive().requires_grad is False and aux.future().requires_grad is False
    assert aux.anchor().requires_grad is True
    assert not torch.equal(aux.positive(), aux.anchor().detach())  # two different shifts
    # InfoNCE of H(anchor) W H(positive)^T: the positive pair of row i is the other view of observation i
    heads = ctx.shared()
    expected, acc = infonce64(heads.state_proj(aux.anchor()), heads.W, heads.state_proj(aux.positive()))
    assert loss.item() == pytest.approx(expected, rel=1e-5)
    assert m["curl_loss"] == pytest.approx(loss.item()) and m["curl_acc"] == pytest.approx(acc)


def test_random_shift_is_integer_crop_of_padded_image():
    torch.manual_seed(3)
    x = torch.arange(32 * 1 * 6 * 6, dtype=torch.float32).reshape(32, 1, 6, 6)
    out = RandomShift(pad=2)(x)
    padded = torch.nn.functional.pad(x, (2, 2, 2, 2), mode="replicate")
    offsets = []
    for b in range(32):
        found = [(i, j) for i in range(5) for j in range(5) if torch.equal(out[b], padded[b, :, i:i + 6, j:j + 6])]
        assert len(found) == 1, b
        offsets.append(found[0])
    # each image gets its own offset: an identity (or one shift for the whole batch) fails here
    assert len(set(offsets)) >= 10 and {i for i, _ in offsets} == {j for _, j in offsets} == set(range(5))


def test_latent_action_dim_rounding():
    assert default_latent_action_dim(12, "upstream") == 16
    assert default_latent_action_dim(12, "paper") == 15
    assert default_latent_action_dim(6, "upstream") == default_latent_action_dim(6, "paper") == 8


def test_critic_sees_latent_actions_and_action_encoder_gets_critic_gradient():
    agent = agent_for(["agent=taco"])
    latent = agent.action_encoder.latent_dim
    assert agent.backbone.critic.q1[0].in_features == agent.cfg.feature_dim + latent
    batch = make_batch()
    h = agent.backbone.encoder(agent.backbone.aug(batch["obs"].float()))
    with torch.no_grad():
        nh = agent.backbone.encoder(agent.backbone.aug(batch["next_obs"].float()))
    agent.backbone.critic_step(h, batch["action"], batch["reward"], batch["discount"], nh, 0)
    assert agent.action_encoder.step[0].weight.grad is not None
    assert agent.action_encoder.step[0].weight.grad.abs().sum() > 0
    assert agent.backbone.encoder.convnet[0].weight.grad.abs().sum() > 0


def test_no_gradient_into_targets_and_actor_update_leaves_encoder():
    agent = agent_for(["agent=taco"])
    assert all(not p.requires_grad for p in agent.backbone.critic_target.parameters())
    target_before = [p.clone() for p in agent.backbone.critic_target.parameters()]
    critic_before = [p.clone() for p in agent.backbone.critic.parameters()]
    actor_before = [p.clone() for p in agent.backbone.actor.parameters()]
    h = agent.backbone.encoder(agent.backbone.aug(make_batch()["obs"].float()))
    agent.backbone.actor_step(h.detach(), 0)
    assert all(torch.equal(a, b) for a, b in zip(target_before, agent.backbone.critic_target.parameters()))
    assert all(torch.equal(a, b) for a, b in zip(critic_before, agent.backbone.critic.parameters()))  # Q is only read
    assert any(not torch.equal(a, b) for a, b in zip(actor_before, agent.backbone.actor.parameters()))
    # inside a full update the actor gets the encoder's output with the gradient stopped
    seen, actor_step = [], agent.backbone.actor_step
    agent.backbone.actor_step = lambda h, step: seen.append(h.requires_grad) or actor_step(h, step)
    agent.update(make_batch(), step=10)
    assert seen == [False]


def test_aux_step_reaches_encoder_action_encoder_and_W():
    agent = agent_for(["agent=taco"])
    agent.backbone.aux_step(make_batch())
    assert agent.backbone.encoder.convnet[0].weight.grad.abs().sum() > 0
    assert agent.action_encoder.seq[0].weight.grad.abs().sum() > 0
    assert agent.backbone.shared.W.grad.abs().sum() > 0
    for name in ("taco", "curl", "reward"):
        assert name in agent.backbone.objectives


def test_full_update_returns_metrics_and_changes_parameters():
    agent = agent_for(["agent=taco"])
    w0 = agent.backbone.encoder.convnet[0].weight.clone()
    metrics = agent.update(make_batch(), step=10)
    assert set(agent.metric_names()) <= set(metrics)
    assert all(v.dim() == 0 and not v.requires_grad and torch.isfinite(v) for v in metrics.values())
    assert not torch.equal(w0, agent.backbone.encoder.convnet[0].weight)


def test_drqv2_has_no_auxiliary_parameters():
    agent = agent_for(["agent=drqv2"])
    assert set(agent.modules()) == {"encoder", "actor", "critic", "critic_target"}
    assert agent.backbone.aux_opt is None and agent.action_encoder is None and agent.backbone.shared is None
    assert agent.backbone.critic.q1[0].in_features == agent.cfg.feature_dim + 4  # raw actions
    metrics = agent.update(make_batch(K=1), step=10)
    assert not any(k.startswith(("taco", "curl", "reward")) for k in metrics)


def test_switches_remove_objectives_and_action_encoder():
    agent = agent_for(["agent.objectives.curl=0", "agent.objectives.reward=0"])
    assert list(agent.backbone.objectives) == ["taco"]
    agent = agent_for(["agent.action_encoder=false"])
    assert agent.action_encoder is None
    assert agent.backbone.critic.q1[0].in_features == agent.cfg.feature_dim + 4
    assert agent.backbone.objectives["taco"].proj_sa[0].in_features == agent.cfg.feature_dim + 3 * 4
    agent.update(make_batch(), step=10)


def test_parameter_counts_match_upstream_shapes():
    agent = agent_for(["agent=taco", "agent.hidden_dim=1024"], A=6)  # cheetah_run: |A|=6, d_u=8, K=3
    counts = dict(agent.parameter_counts())
    assert counts["encoder"] == 9 * 32 * 9 + 32 + 3 * (32 * 32 * 9 + 32)
    trunk = 39200 * 50 + 50 + 2 * 50
    assert counts["actor"] == trunk + (50 * 1024 + 1024) + (1024 * 1024 + 1024) + (1024 * 6 + 6)
    q = (58 * 1024 + 1024) + (1024 * 1024 + 1024) + (1024 + 1)
    assert counts["critic"] == trunk + 2 * q
    assert counts["action_encoder"] == (6 * 64 + 64) + (64 * 8 + 8) + (24 * 24 + 24) + 2 * 24
    assert counts["shared_heads"] == trunk + 50 * 50
    assert counts["objective.taco"] == (74 * 1024 + 1024) + (1024 * 50 + 50)
    assert counts["objective.reward"] == (74 * 1024 + 1024) + (1024 + 1)
