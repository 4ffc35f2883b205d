"""TD3+BC, CQL and IQL (and their +TACO variants) as learners: what each update feeds its loss, in which
space the actions are, where gradients flow, and that the metrics are the train.csv columns."""

from __future__ import annotations

import io

import pytest
import torch

from helpers import offline_batch, offline_learner
from repro.config import paper_defaults
from repro.config.compose import compose, typed
from repro.learners.losses import cql as cql_loss
from repro.learners.losses import iql as iql_loss
from repro.learners.losses import td3bc as td3bc_loss

OBS = (9, 84, 84)
A = 6  # cheetah_run


learner = offline_learner  # an offline learner for cheetah_run under profile=tiny


def batch(lrn, B: int = 8) -> dict[str, torch.Tensor]:
    return offline_batch(B, lrn.cfg.K)


def params(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def changed(before: list[torch.Tensor], module: torch.nn.Module) -> bool:
    return any(not torch.equal(a, b) for a, b in zip(before, module.parameters()))


@pytest.mark.parametrize("agent", ["td3bc", "td3bc_taco", "cql", "cql_taco", "iql"])
def test_update_returns_exactly_the_metric_columns_and_trains_encoder_actor_critic(agent: str):
    lrn = learner(agent)
    b = batch(lrn)
    b["action"].requires_grad_(True)  # a dataset action must never receive a gradient
    bb = lrn.backbone
    enc, act, cri, tgt = params(bb.encoder), params(bb.actor), params(bb.critic), params(bb.critic_target)
    metrics = lrn.update(b, 0)
    assert sorted(metrics) == sorted(lrn.metric_names())
    # detached 0-d tensors: the loops average them on the device (no host sync in update)
    assert all(isinstance(v, torch.Tensor) and v.dim() == 0 and not v.requires_grad for v in metrics.values())
    assert changed(enc, bb.encoder) and changed(act, bb.actor) and changed(cri, bb.critic)
    assert changed(tgt, bb.critic_target)  # the soft target update ran
    assert b["action"].grad is None
    assert ("aux_loss" in metrics) == agent.endswith("_taco")


@pytest.mark.parametrize("agent, critic_action_dim", [("td3bc", A), ("td3bc_taco", None), ("cql", A),
                                                      ("cql_taco", None)])
def test_critic_sees_latent_actions_only_with_taco(agent: str, critic_action_dim: int | None):
    lrn = learner(agent)
    first = lrn.backbone.critic.q1[0]
    latent = lrn.action_encoder.latent_dim if lrn.action_encoder is not None else None
    assert first.in_features == lrn.cfg.feature_dim + (critic_action_dim or latent)
    assert (lrn.action_encoder is not None) == agent.endswith("_taco")


@pytest.mark.parametrize("agent", ["td3bc", "td3bc_taco"])
def test_td3bc_bc_term_in_raw_action_space_against_the_dataset_action(agent: str, monkeypatch):
    lrn = learner(agent)
    b = batch(lrn)
    seen = {}
    real = td3bc_loss.actor_loss

    def spy(q1, q2, policy_action, data_action, alpha, lambda_from):
        seen.update(policy=policy_action.detach().clone(), data=data_action.detach().clone(), alpha=alpha,
                    lambda_from=lambda_from, q1=q1.detach().clone())
        return real(q1, q2, policy_action, data_action, alpha=alpha, lambda_from=lambda_from)

    monkeypatch.setattr(td3bc_loss, "actor_loss", spy)
    lrn.update(b, 0)
    assert seen["policy"].shape == (8, A) and seen["policy"].abs().max() <= 1.0
    assert torch.equal(seen["data"], b["action"])  # the BC target is the raw dataset action
    assert (seen["alpha"], seen["lambda_from"]) == (2.5, "min")


def test_td3bc_lambda_switch_reaches_the_loss():
    lrn = learner("td3bc", **{"agent.td3bc.lambda_from": "q1", "agent.td3bc.alpha": 2.0})
    metrics = lrn.update(batch(lrn), 0)
    # lambda = alpha / mean|Q1| with Q1 at the policy action: positive and finite, and alpha enters it linearly
    assert metrics["actor_lambda"] > 0
    lrn2 = learner("td3bc", **{"agent.td3bc.lambda_from": "q1", "agent.td3bc.alpha": 4.0})
    metrics2 = lrn2.update(batch(lrn2), 0)
    assert metrics2["actor_lambda"] == pytest.approx(2 * metrics["actor_lambda"], rel=1e-5)


@pytest.mark.parametrize("agent", ["cql", "cql_taco"])
def test_cql_uniform_actions_raw_policy_samples_detached_and_encoded_for_the_critic(agent: str, monkeypatch):
    lrn = learner(agent, **{"agent.cql.n_samples": 4})
    b = batch(lrn)
    seen = {}
    real = cql_loss.critic_regularisers

    def spy(critic, h, q_data, uniform, policy, next_policy, alpha, temperature, **kw):
        seen.update(uniform=uniform, policy=policy, next_policy=next_policy, alpha=alpha, kw=kw)
        rows = torch.zeros(3, h.shape[1])
        acts = torch.zeros(3, A)
        q = critic(rows, acts)  # the wrapper: raw actions in, the learner's critic (after u) out
        seen["q_heads"] = len(q)
        return real(critic, h, q_data, uniform, policy, next_policy, alpha, temperature, **kw)

    monkeypatch.setattr(cql_loss, "critic_regularisers", spy)
    metrics = lrn.update(b, 0)
    assert seen["uniform"].shape == (8, 4, A) and seen["uniform"].abs().max() <= 1.0
    assert not seen["policy"].requires_grad and not seen["next_policy"].requires_grad
    assert seen["alpha"] == lrn.cfg.cql.alpha == 0.5  # Table 6: cheetah_run, medium
    assert seen["q_heads"] == 2
    assert metrics["cql_reg_q1"] == pytest.approx(
        0.5 * (metrics["cql_lse_q1"] - metrics["cql_q_data_q1"]), rel=1e-5, abs=1e-6)


def test_cql_policy_samples_do_not_train_the_actor(monkeypatch):
    """With the actor loss switched off, a CQL update leaves the actor exactly as it was."""
    lrn = learner("cql")
    before = params(lrn.backbone.actor)
    monkeypatch.setattr(lrn.backbone, "actor_step", lambda h, step: {"actor_loss": 0.0, "actor_logprob": 0.0,
                                                                      "actor_ent": 0.0})
    lrn.update(batch(lrn), 0)
    assert not changed(before, lrn.backbone.actor)
    # no optimizer steps the actor here, so the check that counts is that no gradient reached it: the policy
    # samples of the regulariser are drawn without gradient (a sample with one would leave a .grad here)
    assert all(p.grad is None for p in lrn.backbone.actor.parameters())


def test_iql_order_value_then_actor_then_critic_and_target_from_v(monkeypatch):
    lrn = learner("iql")
    order: list[str] = []
    for name in ("_value_step", "_actor_step"):
        real = getattr(lrn, name)
        monkeypatch.setattr(lrn, name, lambda *a, _r=real, _n=name, **k: (order.append(_n), _r(*a, **k))[1])
    real_critic = iql_loss.critic_loss
    monkeypatch.setattr(iql_loss, "critic_loss",
                        lambda *a, **k: (order.append("critic"), real_critic(*a, **k))[1])
    v_before = params(lrn.value)
    lrn.update(batch(lrn), 0)
    assert order == ["_value_step", "_actor_step", "critic"]
    assert changed(v_before, lrn.value)
    assert "value" in dict(lrn.parameter_counts()) and "value" in lrn.state_dict()["optimizers"]


def test_iql_critic_target_is_r_plus_discount_v_next(monkeypatch):
    """The target is r + discount * V(h'), h' the encoded next frames (before the critic step moves the encoder)
    and V after the value step (the JAX order), without gradient."""
    lrn = learner("iql")
    monkeypatch.setattr(lrn.backbone, "aug", lambda x: x)  # no random shift, so h' can be recomputed here
    b = batch(lrn)
    with torch.no_grad():
        next_h = lrn.backbone.encoder(b["next_obs"].float())
    seen = {}
    real = iql_loss.critic_target

    def spy(reward, discount, next_v):
        seen["target"] = real(reward, discount, next_v)
        seen["next_v"] = next_v
        return seen["target"]

    monkeypatch.setattr(iql_loss, "critic_target", spy)
    lrn.update(b, 0)
    with torch.no_grad():  # V is not stepped after the value step: its weights now are the ones the target used
        expected_v = lrn.value(next_h)
    assert torch.allclose(seen["next_v"], expected_v, rtol=1e-5, atol=1e-6)
    assert torch.allclose(seen["target"], b["reward"] + b["discount"] * expected_v, rtol=1e-5, atol=1e-6)
    assert not seen["next_v"].requires_grad


def test_state_dict_round_trip_gives_the_same_next_update():
    """Through torch.save/load with weights_only, as a checkpoint (an in-process dict would share Adam state)."""
    a = learner("cql_taco")
    a.update(batch(a), 0)
    buf = io.BytesIO()
    torch.save(a.state_dict(), buf)
    buf.seek(0)
    state = torch.load(buf, weights_only=True)
    b = learner("cql_taco")
    b.load_state_dict(state)
    torch.manual_seed(9)
    ma = a.update(batch(a), 1)
    torch.manual_seed(9)
    mb = b.update(batch(b), 1)
    assert ma == mb


def test_cql_alpha_comes_from_table_6_and_an_override_wins():
    assert typed(compose(["agent=cql", "task=walker_run", "offline.dataset=full-replay"])).agent.cql.alpha == \
        paper_defaults.cql_alpha("walker_run", "full-replay")
    assert typed(compose(["agent=cql", "task=walker_run", "offline.dataset=medium",
                          "agent.cql.alpha=3.0"])).agent.cql.alpha == 3.0
