"""The offline learners against their reference code (issue 16): V-D4RL's CQL regulariser and noise schedule,
the JAX IQL update order. Known answers come from the references' equations in float64, not from the code
under test (docs/deviations.md, "Offline references")."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch

from helpers import offline_batch, offline_learner
from repro.config.compose import compose, typed
from repro.learners import build_learner
from repro.learners.losses import cql as cql_loss
from repro.learners.losses import iql as iql_loss

OBS = (9, 84, 84)
A = 6  # cheetah_run


learner = offline_learner  # an offline learner for cheetah_run under profile=tiny


def batch(B: int = 8, K: int = 3) -> dict[str, torch.Tensor]:
    return offline_batch(B, K)


def vd4rl_sigma(update: int) -> float:
    """V-D4RL's utils.schedule('linear(1.0,0.1,250000)', step) at its loop step 2u (update_every_steps 2)."""
    mix = float(np.clip(np.float64(2 * update) / 250000.0, 0.0, 1.0))
    return (1.0 - mix) * 1.0 + mix * 0.1


# ----------------------------------------------------------------------------- 1. CQL samples clipped
@pytest.mark.parametrize("agent", ["cql", "cql_taco"])
def test_cql_policy_samples_lie_within_stddev_clip_of_the_mean(agent: str, monkeypatch):
    """With the policy mean forced to 0 and sigma 1 (update 0), every one of the 2 x B x N x A policy samples
    must lie in [-0.3, 0.3] (V-D4RL: sample(clip=stddev_clip)); unclipped, most would not."""
    lrn = learner(agent)
    last = lrn.backbone.actor.policy[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
    seen = {}
    real = cql_loss.critic_regularisers

    def spy(critic, h, q_data, uniform, policy, next_policy, *a, **k):
        seen.update(policy=policy.clone(), next_policy=next_policy.clone())
        return real(critic, h, q_data, uniform, policy, next_policy, *a, **k)

    monkeypatch.setattr(cql_loss, "critic_regularisers", spy)
    lrn.update(batch(), 0)
    assert lrn.stddev(0) == 1.0 and lrn.cfg.stddev_clip == 0.3
    samples = torch.cat([seen["policy"].flatten(), seen["next_policy"].flatten()])
    assert samples.numel() == 2 * 8 * 10 * A
    assert samples.abs().max().item() <= 0.3 + 1e-6
    assert samples.abs().max().item() > 0.25  # the noise is there, only clipped


# ----------------------------------------------------------------------------- 2. data Q in the logsumexp
def test_cql_regulariser_equals_vd4rl_equation_with_the_data_q_in_the_logsumexp(monkeypatch):
    """V-D4RL drqbc/cql.py, no importance sampling: for each head
    R = w * (T * mean_b logsumexp([Q_rand, Q(a_data), Q_next, Q_curr] / T) - mean_b Q(a_data)), in float64."""
    lrn = learner("cql")
    seen: dict = {}
    real = cql_loss.critic_regularisers

    def spy(critic, h, q_data, uniform, policy, next_policy, alpha, temperature, **k):
        b, n, a = uniform.shape
        with torch.no_grad():
            rows = h.repeat_interleave(n, dim=0)
            qs = [critic(rows, x.reshape(b * n, a)) for x in (uniform, policy, next_policy)]
        seen.update(q_data=[q.detach().double().reshape(b) for q in q_data], alpha=alpha, T=temperature, n=n,
                    q_samples=[[qs[j][i].double().reshape(b, n) for j in range(3)] for i in range(2)])
        return real(critic, h, q_data, uniform, policy, next_policy, alpha, temperature, **k)

    monkeypatch.setattr(cql_loss, "critic_regularisers", spy)
    metrics = lrn.update(batch(), 0)
    T, w = seen["T"], seen["alpha"]
    for i in range(2):
        q_d = seen["q_data"][i].numpy()
        q_rand, q_curr, q_next = (x.numpy() for x in seen["q_samples"][i])
        cat = np.concatenate([q_rand, q_d[:, None], q_next, q_curr], axis=1) / T
        top = cat.max(axis=1, keepdims=True)
        lse = (top[:, 0] + np.log(np.exp(cat - top).sum(axis=1))).mean() * T
        expected = w * (lse - q_d.mean())
        assert metrics[f"cql_reg_q{i + 1}"] == pytest.approx(expected, rel=1e-5, abs=1e-6)
        assert cat.shape[1] == 3 * seen["n"] + 1


# ----------------------------------------------------------------------------- 3. the schedule's unit
@pytest.mark.parametrize("agent", ["td3bc", "td3bc_taco", "cql", "cql_taco", "iql"])
def test_offline_sigma_at_update_u_is_vd4rl_schedule_at_loop_step_2u(agent: str):
    lrn = learner(agent)
    for u, hand in [(0, 1.0), (1000, None), (62_500, 0.55), (100_000, 0.28), (125_000, 0.1), (200_000, 0.1)]:
        assert lrn.stddev(u) == pytest.approx(vd4rl_sigma(u), rel=1e-12, abs=1e-12), u
        if hand is not None:
            assert lrn.stddev(u) == pytest.approx(hand, rel=1e-12), u


@pytest.mark.parametrize("agent", ["td3bc", "cql", "iql"])
def test_the_update_acts_with_the_vd4rl_sigma(agent: str, monkeypatch):
    """The std the actor is called with inside update(batch, 100000) is V-D4RL's 0.28, not 0.64."""
    lrn = learner(agent)
    stds: list[float] = []
    real = lrn.backbone.actor.forward
    monkeypatch.setattr(lrn.backbone.actor, "forward", lambda h, std: (stds.append(float(std)), real(h, std))[1])
    lrn.update(batch(), 100_000)
    assert stds and all(s == pytest.approx(0.28, rel=1e-12) for s in stds)


def test_online_schedule_still_counts_agent_steps():
    rc = typed(compose(["agent=taco", "task=cheetah_run"]))
    sched = rc.agent.stddev_schedule
    assert sched.step_scale == 1
    for step in (0, 1, 12_345, sched.duration // 2, sched.duration, 2 * sched.duration):
        mix = min(step / sched.duration, 1.0)
        assert sched(step) == (1.0 - mix) * sched.start + mix * sched.end


# ----------------------------------------------------------------------------- 4. IQL's order
def _iql_values_used(lrn, monkeypatch) -> dict:
    """Run one update, recording the V the actor's advantage and the critic's target were given and every
    input the value network saw."""
    seen: dict = {"inputs": []}
    real_actor, real_target = iql_loss.actor_loss, iql_loss.critic_target

    def actor_spy(log_prob, tq1, tq2, v, **k):
        seen["actor_v"] = v.detach().clone()
        return real_actor(log_prob, tq1, tq2, v, **k)

    def target_spy(reward, discount, next_v):
        seen["next_v"] = next_v.detach().clone()
        return real_target(reward, discount, next_v)

    monkeypatch.setattr(iql_loss, "actor_loss", actor_spy)
    monkeypatch.setattr(iql_loss, "critic_target", target_spy)
    seen["value_before"] = copy.deepcopy(lrn.value)  # before the hook, so the copy records nothing
    hook = lrn.value.register_forward_hook(lambda m, inp, out: seen["inputs"].append(inp[0].detach().clone()))
    lrn.update(batch(), 0)
    hook.remove()
    return seen


def _v_of(net, inputs, target: torch.Tensor) -> torch.Tensor:
    """V(x) by ``net`` for the recorded input x whose batch the target came from (h or h')."""
    with torch.no_grad():
        outs = [net(x) for x in inputs]
    # the recorded input that gives the value closest to the target under either network identifies it
    return min(outs, key=lambda o: (o - target).abs().max().item())


def test_iql_actor_advantage_and_critic_target_use_v_after_the_value_step(monkeypatch):
    """JAX learner.py: new_value = update_v(...); the actor gets new_value, update_q gets new_value."""
    lrn = learner("iql")
    seen = _iql_values_used(lrn, monkeypatch)
    after, before = lrn.value, seen["value_before"]
    h, inputs = seen["inputs"][0], seen["inputs"]  # the value loss's V(h) is the first call
    with torch.no_grad():
        assert not torch.allclose(after(h), before(h))  # the value step moved V
        assert torch.equal(seen["actor_v"], after(h))
    next_v = seen["next_v"]
    assert torch.equal(_v_of(after, inputs, next_v), next_v)
    with torch.no_grad():
        assert all(not torch.equal(before(x), next_v) for x in inputs)


def test_iql_corl_switch_uses_v_before_the_value_step(monkeypatch):
    lrn = learner("iql", **{"agent.iql.value_for_targets": "before"})
    seen = _iql_values_used(lrn, monkeypatch)
    before, inputs = seen["value_before"], seen["inputs"]
    with torch.no_grad():
        assert torch.equal(seen["actor_v"], before(inputs[0]))
        assert any(torch.equal(before(x), seen["next_v"]) for x in inputs)
        assert not torch.allclose(lrn.value(inputs[0]), before(inputs[0]))


def test_iql_learner_refuses_an_unknown_order():
    """Built from a typed config directly (compose already refuses it, see below)."""
    rc = typed(compose(["agent=iql", "task=cheetah_run", "profile=tiny", "offline.dataset=medium"]))
    rc.agent.iql.value_for_targets = "sideways"
    with pytest.raises(ValueError, match="'sideways' is not a valid ValueForTargets"):
        build_learner(rc.agent, OBS, A, "cpu")


def test_iql_actor_cosine_lr_switch_is_optax_cosine_decay():
    """optax.cosine_decay_schedule(lr, 4) at counts 0..5: lr * (1 + cos(pi * min(c, 4) / 4)) / 2."""
    lrn = learner("iql", **{"agent.iql.actor_lr_cosine_updates": 4})
    base = lrn.cfg.lr
    hand = [1.0, (1 + math.sqrt(0.5)) / 2, 0.5, (1 - math.sqrt(0.5)) / 2, 0.0, 0.0]
    for u, factor in enumerate(hand):
        lrn.update(batch(), u)
        assert lrn.backbone.actor_opt.param_groups[0]["lr"] == pytest.approx(base * factor, rel=1e-12, abs=1e-15)
    assert lrn.backbone.critic_opt.param_groups[0]["lr"] == base and lrn.value_opt.param_groups[0]["lr"] == base
    default = learner("iql")
    default.update(batch(), 3)
    assert default.backbone.actor_opt.param_groups[0]["lr"] == base  # DrQ-v2's constant rate by default


def test_iql_learned_log_std_switch_is_the_jax_actor(monkeypatch):
    """NormalTanhPolicy(state_dependent_std=False): log pi(a|s) = sum_i log N(a_i; tanh mu_i, exp(log_std_i)),
    log_std zeros at start, trained by the actor's optimizer; checked in float64 at the first update."""
    lrn = learner("iql", **{"agent.iql.learned_log_std": True})
    assert dict(lrn.parameter_counts())["log_std"] == A and "log_std" in lrn.state_dict()["modules"]
    actor_before = copy.deepcopy(lrn.backbone.actor)
    seen: dict = {}
    real_actor = iql_loss.actor_loss

    def actor_spy(log_prob, tq1, tq2, v, **k):
        seen["log_prob"] = log_prob.detach().clone()
        return real_actor(log_prob, tq1, tq2, v, **k)

    monkeypatch.setattr(iql_loss, "actor_loss", actor_spy)
    inputs: list[torch.Tensor] = []
    hook = lrn.value.register_forward_hook(lambda m, inp, out: inputs.append(inp[0].detach().clone()))
    b = batch()
    lrn.update(b, 0)
    hook.remove()
    with torch.no_grad():
        mean = actor_before(inputs[0], 1.0).mean.double().numpy()
    a = b["action"].double().numpy()
    expected = (-0.5 * (a - mean) ** 2 - 0.5 * math.log(2 * math.pi)).sum(-1, keepdims=True)
    np.testing.assert_allclose(seen["log_prob"].double().numpy(), expected, rtol=1e-5, atol=1e-5)
    assert lrn.log_std.log_std.detach().abs().sum() > 0  # trained
    default = learner("iql")
    assert default.log_std is None and "log_std" not in dict(default.parameter_counts())


@pytest.mark.parametrize("override, needle", [("agent.iql.value_for_targets=sideways", "value_for_targets"),
                                              ("agent.iql.actor_lr_cosine_updates=0", "actor_lr_cosine_updates"),
                                              ("agent.stddev_schedule.step_scale=0", "step_scale")])
def test_bad_switch_values_are_one_line_config_errors(override: str, needle: str):
    from repro.config.compose import ConfigError

    with pytest.raises(ConfigError, match=f"{needle}.*(is not one of|must be)") as err:
        compose(["agent=iql", "task=cheetah_run", "offline.dataset=medium", override])
    assert "\n" not in str(err.value)


NEW_KEYS = [("agent", "stddev_schedule", "step_scale"), ("agent", "cql", "clip_policy_samples"),
            ("agent", "iql", "value_for_targets"), ("agent", "iql", "actor_lr_cosine_updates"),
            ("agent", "iql", "learned_log_std"), ("agent", "dt", "activation"), ("agent", "dt", "init"),
            ("agent", "dt", "ff_dropout"), ("agent", "dt", "action_pad")]


def _pre_issue_16_run(tmp_path, overrides: list[str]):
    """A run directory whose config.yaml lacks the keys issue 16 added (as one written before it: format 1, every
    learner's section)."""
    import yaml
    from omegaconf import OmegaConf

    from repro.runs.rundir import CONFIG

    cfg = compose(overrides + [f"runtime.results_root={tmp_path}"])
    data = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    for a, b, c in NEW_KEYS:
        if b in data[a]:  # since config format 4 a run composes its own learner's section only
            data[a][b].pop(c)
    (tmp_path / CONFIG).write_text(yaml.safe_dump(data))
    return cfg


@pytest.mark.parametrize("overrides, refused", [
    (["agent=taco", "task=cheetah_run"], []),  # online: nothing changed, still resumes
    (["agent=bc", "task=cheetah_run", "offline.dataset=medium"], []),  # BC does not read the schedule
    (["agent=td3bc", "task=cheetah_run", "offline.dataset=medium"], ["agent.stddev_schedule.step_scale"]),
    (["agent=cql", "task=cheetah_run", "offline.dataset=medium"],
     ["agent.cql.clip_policy_samples", "agent.stddev_schedule.step_scale"]),
    (["agent=iql", "task=cheetah_run", "offline.dataset=medium"],
     ["agent.iql.value_for_targets", "agent.stddev_schedule.step_scale"]),
    (["agent=dt", "task=cheetah_run", "offline.dataset=medium"],
     ["agent.dt.action_pad", "agent.dt.activation", "agent.dt.ff_dropout", "agent.dt.init"]),
])
def test_a_run_written_before_issue_16_is_not_resumed_with_the_new_behaviour(tmp_path, overrides, refused):
    from repro.runs.rundir import config_diff

    cfg = _pre_issue_16_run(tmp_path, overrides)
    assert sorted(d.path for d in config_diff(tmp_path, cfg)) == refused


# ----------------------------------------------------------------------------- IQL reward scaling (JAX code)
def _critic_reward(lrn, b, monkeypatch) -> torch.Tensor:
    seen = {}
    real = iql_loss.critic_target

    def spy(reward, discount, next_v):
        seen["reward"] = reward.detach().clone()
        return real(reward, discount, next_v)

    monkeypatch.setattr(iql_loss, "critic_target", spy)
    lrn.update(b, 0)
    return seen["reward"]


def test_iql_return_range_scaling_is_the_jax_normalize(monkeypatch):
    """train_offline.py's normalize(): rewards / (best - worst episode return) x 1000; by hand: returns 10, 50, 30
    give x 25. The default (DrQ-v2, V-D4RL) leaves them as they are."""
    b = batch()
    scaled = learner("iql", **{"agent.iql.reward_scaling": "return_range"})
    scaled.set_dataset_returns([10.0, 50.0, 30.0])
    assert scaled.reward_scale == 25.0
    torch.testing.assert_close(_critic_reward(scaled, b, monkeypatch), b["reward"] * 25.0)
    plain = learner("iql")
    plain.set_dataset_returns([10.0, 50.0, 30.0])
    torch.testing.assert_close(_critic_reward(plain, b, monkeypatch), b["reward"])
    with pytest.raises(ValueError, match="different returns"):
        scaled.set_dataset_returns([3.0, 3.0])


def test_iql_reward_scaling_bad_value_is_one_config_line():
    from repro.config.compose import ConfigError

    with pytest.raises(ConfigError, match="agent.iql.reward_scaling"):
        compose(["agent=iql", "task=cheetah_run", "agent.iql.reward_scaling=minmax"])


@pytest.mark.slow
def test_iql_run_scales_by_its_datasets_return_range_and_records_it(tmp_path):
    """The training entry point hands the dataset's episode returns to the learner: resolved.json records the
    factor, 1000 / (best - worst return) of the manifest, computed here from the manifest by hand."""
    import json

    from offline_fixtures import write_dataset
    from repro.train import api

    folder = tmp_path / "datasets" / "cheetah_run" / "medium"
    write_dataset(folder, task="cheetah_run", action_dim=6, best_return=200.0)
    returns = [e["return"] for e in json.loads((folder / "manifest.json").read_text())["episodes"]]
    run = api.train(["agent=iql", "task=cheetah_run", "profile=tiny", "runtime.threads=1", "offline.dataset=medium",
                     "offline.updates=2", "offline.eval_every_updates=2", "offline.eval_episodes=1",
                     "env.max_episode_frames=10", "agent.iql.reward_scaling=return_range",
                     f"runtime.results_root={tmp_path}"], echo=lambda s: None)
    resolved = json.loads((run / "resolved.json").read_text())
    assert resolved["iql_reward_scale"] == pytest.approx(1000.0 / (max(returns) - min(returns)))
