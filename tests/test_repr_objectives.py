"""SPR, ATC, DRIML and CURL-only (Table 2): known answers, gradient flow, momentum targets, configs, tiny runs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch
import yaml
from torch import nn

from repro.agent.agent import Agent
from repro.agent.objectives import AuxBatch
from repro.agent.objectives.atc import ATCObjective
from repro.agent.objectives.driml import DRIMLObjective, first_action_only
from repro.agent.objectives.spr import MomentumTarget, SPRObjective, negative_cosine
from repro.config.compose import CONF_DIR, compose, typed
from repro.config.schema import ATCParams, SPRParams

OBS = (9, 32, 32)  # small frames: the encoder gives 32 x 9 x 9 features
A = 3
NEW_AGENTS = ("spr", "atc", "driml", "curl")


def make_batch(B: int = 6, K: int = 3, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    u8 = lambda: torch.randint(0, 256, (B, *OBS), dtype=torch.uint8, generator=g)  # noqa: E731
    return {"obs": u8(), "next_obs": u8(), "future_obs": u8(), "action": torch.rand(B, A, generator=g) * 2 - 1,
            "action_seq": torch.rand(B, K, A, generator=g) * 2 - 1, "reward": torch.rand(B, 1, generator=g),
            "discount": torch.full((B, 1), 0.99 ** 3), "reward_ksum": torch.rand(B, 1, generator=g) * 3,
            "future_obs_seq": torch.stack([u8() for _ in range(K)], 1)}


def agent_for(overrides: list[str], seed: int = 0) -> Agent:
    torch.manual_seed(seed)
    rc = typed(compose(["agent.hidden_dim=32"] + overrides))
    return Agent(rc.agent, OBS, A)


def aux_for(agent: Agent, batch: dict[str, torch.Tensor]) -> AuxBatch:
    bb = agent.backbone
    return AuxBatch(batch, bb.encoder, bb.aug, bb.encode_action_sequence, agent.cfg.reward_target,
                    bb.encode_action)


def grad_norm(module: nn.Module) -> float:
    return sum(float(p.grad.abs().sum()) for p in module.parameters() if p.grad is not None)


def has_no_grad(module: nn.Module) -> bool:
    return all(p.grad is None and not p.requires_grad for p in module.parameters())


def snapshot(module: nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def plain_aux(agent: Agent, batch: dict[str, torch.Tensor]) -> AuxBatch:
    """Like aux_for but without augmentation, so every view can be recomputed outside the objective."""
    bb = agent.backbone
    return AuxBatch(batch, bb.encoder, lambda x: x, bb.encode_action_sequence, agent.cfg.reward_target,
                    bb.encode_action)


def f64(t: torch.Tensor) -> np.ndarray:
    return t.detach().numpy().astype(np.float64)


def neg_cos64(pred: np.ndarray, target: np.ndarray) -> float:
    """-mean over all leading axes of cos(pred, target) along the last axis, by hand."""
    dots = (pred * target).sum(-1)
    return float(-(dots / (np.linalg.norm(pred, axis=-1) * np.linalg.norm(target, axis=-1))).mean())


# ----------------------------------------------------------------------------- known answers


def test_negative_cosine_known_answer():
    x = torch.tensor([[1.0, 0.0], [3.0, 0.0], [0.0, 2.0]])
    y = torch.tensor([[1.0, 1.0], [-2.0, 0.0], [0.0, 5.0]])
    # cosines: 1/sqrt(2), -1, 1  -> loss = -mean
    expected = -(1 / math.sqrt(2) - 1 + 1) / 3
    assert negative_cosine(x, y).item() == pytest.approx(expected, rel=1e-6)
    assert negative_cosine(y, y).item() == pytest.approx(-1.0, rel=1e-6)  # scale-free, minimum -1


def test_momentum_target_ema_arithmetic():
    online = nn.Linear(2, 2)
    with torch.no_grad():
        online.weight.fill_(1.0)
        online.bias.fill_(1.0)
    target = MomentumTarget({"lin": online}, momentum=0.9)
    with torch.no_grad():
        target["lin"].weight.zero_()
        target["lin"].bias.zero_()
    target.update()  # 0.9 * 0 + 0.1 * 1
    assert torch.allclose(target["lin"].weight, torch.full((2, 2), 0.1))
    target.update()  # 0.9 * 0.1 + 0.1 * 1
    assert torch.allclose(target["lin"].bias, torch.full((2,), 0.19))
    assert not any(p.requires_grad for p in target.parameters())
    assert len(list(target.parameters())) == 2  # the online module is not registered under the target
    assert online.weight.requires_grad
    with pytest.raises(ValueError):
        MomentumTarget({"lin": online}, momentum=1.0)


def test_atc_logits_known_answer():
    agent = agent_for(["agent=atc", "agent.feature_dim=2", "agent.objective_params.atc.predictor_hidden=4"])
    atc = agent.backbone.objectives["atc"]
    assert isinstance(atc, ATCObjective)
    with torch.no_grad():
        atc.predictor[-1].weight.zero_()  # residual predictor -> identity
        atc.predictor[-1].bias.zero_()
        atc.W.copy_(torch.tensor([[1.0, 0.0], [0.0, 2.0]]))
    c = torch.tensor([[1.0, 1.0], [2.0, 0.0]])
    t = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    raw = torch.tensor([[1.0, 2.0], [2.0, 0.0]])  # c W t^T by hand
    assert torch.allclose(atc.logits(c, t), raw - raw.max(dim=1, keepdim=True).values)
    with torch.no_grad():  # the predictor's output is added to the anchor (ATC's residual MLP)
        atc.predictor[-1].bias.copy_(torch.tensor([1.0, 0.0]))
    raw = torch.tensor([[2.0, 2.0], [3.0, 0.0]])
    assert torch.allclose(atc.logits(c, t), raw - raw.max(dim=1, keepdim=True).values)


def test_first_action_only_masks_later_steps():
    seq = torch.arange(1, 13, dtype=torch.float32).reshape(2, 3, 2)
    out = first_action_only(seq)
    assert torch.equal(out[:, 0], seq[:, 0]) and torch.equal(out[:, 1:], torch.zeros(2, 2, 2))
    one = seq[:, :1]
    assert torch.equal(first_action_only(one), one)


# ----------------------------------------------------------------------------- DRIML vs TACO


def test_driml_loss_equals_taco_at_k1_on_same_weights_and_batch():
    agent = agent_for(["agent=taco", "agent.K=1", "+agent.objectives.driml=1.0"])
    taco, driml = agent.backbone.objectives["taco"], agent.backbone.objectives["driml"]
    assert isinstance(driml, DRIMLObjective)
    driml.proj_sa.load_state_dict(taco.proj_sa.state_dict())
    aux = aux_for(agent, make_batch(K=1))
    loss_t, m_t = taco(aux)
    loss_d, m_d = driml(aux)
    assert torch.equal(loss_t, loss_d)
    assert m_t["taco_acc"] == m_d["driml_acc"]
    agent = agent_for(["agent=taco", "agent.K=3", "+agent.objectives.driml=1.0"])  # with K=3 they differ
    agent.backbone.objectives["driml"].proj_sa.load_state_dict(agent.backbone.objectives["taco"].proj_sa.state_dict())
    aux = aux_for(agent, make_batch(K=3))
    assert agent.backbone.objectives["taco"](aux)[0].item() != agent.backbone.objectives["driml"](aux)[0].item()


def test_driml_agent_is_the_taco_agent_at_k1():
    """Same seed, K=1: agent=driml builds TACO's weights and reports TACO's losses on the same batch."""
    taco = agent_for(["agent=taco", "agent.K=1"], seed=5)
    driml = agent_for(["agent=driml", "agent.K=1"], seed=5)
    for name, mod in taco.modules().items():
        other = driml.modules()[name.replace("objective.taco", "objective.driml")]
        for (k, v), (k2, v2) in zip(mod.state_dict().items(), other.state_dict().items()):
            assert k == k2 and torch.equal(v, v2), (name, k)
    batch = make_batch(K=1)
    torch.manual_seed(7)
    m_t = taco.backbone.aux_step(batch)
    torch.manual_seed(7)
    m_d = driml.backbone.aux_step(batch)
    assert m_t["taco_loss"] == m_d["driml_loss"] and m_t["aux_loss"] == m_d["aux_loss"]


def test_driml_uses_only_the_first_action_at_k3():
    agent = agent_for(["agent=driml", "agent.K=3", "agent.objectives.curl=0", "agent.objectives.reward=0"])
    batch = make_batch(K=3)
    batch["action_seq"].requires_grad_(True)
    loss, _ = agent.backbone.objectives["driml"](aux_for(agent, batch))
    loss.backward()
    g = batch["action_seq"].grad
    assert g[:, 0].abs().sum() > 0 and torch.equal(g[:, 1:], torch.zeros_like(g[:, 1:]))
    assert grad_norm(agent.action_encoder) > 0 and grad_norm(agent.backbone.encoder) > 0
    # changing the later actions leaves the loss unchanged (same augmentations through the memo)
    aux = aux_for(agent, make_batch(K=3))
    before = agent.backbone.objectives["driml"](aux)[0].item()
    aux.batch["action_seq"][:, 1:] = 0.5
    aux._cache.pop("u_first")
    assert agent.backbone.objectives["driml"](aux)[0].item() == pytest.approx(before, abs=0.0)


# ----------------------------------------------------------------------------- SPR


def test_spr_gradient_flow_and_momentum_target():
    m = 0.9
    agent = agent_for(["agent=spr", f"agent.objective_params.spr.momentum={m}"])
    spr = agent.backbone.objectives["spr"]
    assert isinstance(spr, SPRObjective) and spr.target is not None
    batch = make_batch()
    loss, metrics = spr(plain_aux(agent, batch))
    assert metrics["spr_loss"] == pytest.approx(loss.item())
    # at construction the momentum target is a copy of (f, H, g): its latent of o_{t+k} is the online one's
    with torch.no_grad():
        bb = agent.backbone
        online = torch.stack([spr.projection(bb.shared.state_proj(bb.encoder(batch["future_obs_seq"][:, k]
                                                                             .float()))) for k in range(3)], 1)
    expected = neg_cos64(f64(spr.predict(plain_aux(agent, batch))), f64(online))
    assert loss.item() == pytest.approx(expected, rel=1e-5)
    agent.backbone.aux_opt.zero_grad(set_to_none=True)
    loss.backward()
    for mod in (bb.encoder, agent.action_encoder, bb.shared.state_proj, spr.transition, spr.projection,
                spr.prediction):
        assert grad_norm(mod) > 0
    assert has_no_grad(spr.target)
    old_target, old_online = snapshot(spr.target), snapshot(agent.backbone.encoder)
    agent.backbone.aux_opt.step()
    assert all(torch.equal(a, b) for a, b in zip(old_target, snapshot(spr.target)))  # the optimizer leaves it
    assert any(not torch.equal(a, b) for a, b in zip(old_online, snapshot(agent.backbone.encoder)))
    spr.after_update()
    online = [p.detach() for p in agent.backbone.encoder.parameters()]
    for old, new, on in zip(old_target[:len(online)], snapshot(spr.target["encoder"]), online):
        assert torch.allclose(new, m * old + (1 - m) * on, atol=1e-7)


def test_spr_default_momentum_zero_is_the_online_network_without_gradient():
    agent = agent_for(["agent=spr"])
    spr = agent.backbone.objectives["spr"]
    assert spr.momentum == 0.0 and spr.target is None  # SPR with augmentation: tau = 0
    aux = aux_for(agent, make_batch())
    target = spr.target_projection(aux)
    assert not target.requires_grad and target.shape[:2] == (6, 3)  # one target per rollout step
    for k in (1, 2, 3):
        assert torch.equal(target[:, k - 1], spr.projection(agent.backbone.shared.state_proj(aux.future_at(k))))
    own = {id(p) for p in spr.parameters()} - {id(p) for p in agent.backbone.shared.parameters()}
    heads = [spr.transition, spr.projection, spr.prediction]
    assert own == {id(p) for mod in heads for p in mod.parameters()}  # no copy of the encoder


def test_spr_rollout_predicts_every_step_with_per_step_actions():
    agent = agent_for(["agent=spr"])
    spr = agent.backbone.objectives["spr"]
    assert spr.rollout and spr.needs_future_seq and agent.sample_options == {"future_seq": True}
    assert spr.transition[0].in_features == agent.cfg.feature_dim + agent.action_encoder.latent_dim
    aux = aux_for(agent, make_batch())
    pred, target = spr.predict(aux), spr.target_projection(aux)
    assert pred.shape == target.shape and pred.shape[1] == 3
    loss, _ = spr(aux)
    per_step = [negative_cosine(pred[:, k], target[:, k]).item() for k in range(3)]
    assert loss.item() == pytest.approx(sum(per_step) / 3, rel=1e-5)
    # the k-th prediction depends on a_t..a_{t+k-1} only (identity augmentation: deterministic views)
    batch = make_batch()
    changed = {k: v.clone() for k, v in batch.items()}
    changed["action_seq"][:, 2] = -changed["action_seq"][:, 2]

    def plain(b):
        return AuxBatch(b, agent.backbone.encoder, lambda x: x, agent.backbone.encode_action_sequence, "nstep",
                        agent.backbone.encode_action)

    p1, p2 = spr.predict(plain(batch)), spr.predict(plain(changed))
    assert torch.equal(p1[:, :2], p2[:, :2]) and not torch.allclose(p1[:, 2], p2[:, 2])


def test_spr_one_shot_variant_and_replay_without_future_seq():
    agent = agent_for(["agent=spr", "agent.objective_params.spr.rollout=false"])
    spr = agent.backbone.objectives["spr"]
    assert not spr.rollout and agent.sample_options == {"future_seq": False}
    assert spr.transition[0].in_features == agent.cfg.feature_dim + 3 * agent.action_encoder.latent_dim
    batch = make_batch()
    del batch["future_obs_seq"]
    loss, _ = spr(plain_aux(agent, batch))
    # one prediction of o_{t+K} from (z_t, u_t..u_{t+K-1}) against the stopped-gradient online latent of o_{t+K}
    with torch.no_grad():
        z = agent.backbone.shared.state_proj(agent.backbone.encoder(batch["obs"].float()))
        u = agent.backbone.encode_action_sequence(batch["action_seq"])
        pred = spr.prediction(spr.projection(spr.transition(torch.cat([z, u], -1))))
        target = spr.projection(agent.backbone.shared.state_proj(agent.backbone.encoder(batch["future_obs"].float())))
    assert loss.item() == pytest.approx(neg_cos64(f64(pred), f64(target)), rel=1e-5)
    with pytest.raises(ValueError, match="future_obs_seq"):
        agent_for(["agent=spr"]).backbone.objectives["spr"](aux_for(agent_for(["agent=spr"]), batch))


def test_spr_projection_dim_and_unknown_keys():
    agent = agent_for(["agent=spr", "agent.objective_params.spr.projection_dim=8"])
    assert agent.backbone.objectives["spr"].prediction.weight.shape == (8, 8)
    with pytest.raises(ValueError, match="momentun"):
        agent_for(["agent=spr", "+agent.objective_params.spr.momentun=0.5"])


# ----------------------------------------------------------------------------- ATC


def test_atc_gradient_flow_no_actions_and_momentum_target():
    agent = agent_for(["agent=atc", "agent.objectives.curl=0", "agent.objectives.reward=0",
                       "agent.objective_params.atc.predictor_hidden=16"])
    atc = agent.backbone.objectives["atc"]
    m = atc.target.momentum
    assert m == pytest.approx(0.99)
    batch = make_batch()
    loss, metrics = atc(plain_aux(agent, batch))
    # by hand in float64: anchor c = H(f(o_t)), p = c + W2 relu(W1 c + b1) + b2, positive c~ = H_m(f_m(o_{t+K}))
    # (= the online H(f(o_{t+K})) before any update), InfoNCE of p W c~^T against the diagonal
    with torch.no_grad():
        c = f64(agent.backbone.shared.state_proj(agent.backbone.encoder(batch["obs"].float())))
        target = f64(agent.backbone.shared.state_proj(agent.backbone.encoder(batch["future_obs"].float())))
    l1, l2 = atc.predictor[0], atc.predictor[2]
    p = c + np.maximum(c @ f64(l1.weight).T + f64(l1.bias), 0) @ f64(l2.weight).T + f64(l2.bias)
    logits = p @ f64(atc.W) @ target.T
    top = logits.max(1, keepdims=True)
    log_soft = logits - top - np.log(np.exp(logits - top).sum(1, keepdims=True))
    assert loss.item() == pytest.approx(float(-np.diag(log_soft).mean()), rel=1e-5)
    assert metrics["atc_loss"] == pytest.approx(loss.item())
    assert metrics["atc_acc"] == pytest.approx(float((logits.argmax(1) == np.arange(len(logits))).mean()))
    agent.backbone.aux_opt.zero_grad(set_to_none=True)
    loss.backward()
    assert grad_norm(agent.backbone.encoder) > 0 and grad_norm(agent.backbone.shared.state_proj) > 0
    assert grad_norm(atc.predictor) > 0 and atc.W.grad is not None
    assert all(p.grad is None for p in agent.action_encoder.parameters())  # no actions in ATC's positive pair
    assert has_no_grad(atc.target)
    old = snapshot(atc.target)
    agent.backbone.aux_opt.step()
    assert all(torch.equal(a, b) for a, b in zip(old, snapshot(atc.target)))
    atc.after_update()
    bb = agent.backbone
    online = [p.detach() for mod in (bb.encoder, bb.shared.state_proj) for p in mod.parameters()]
    for o, new, on in zip(old, snapshot(atc.target), online):
        assert torch.allclose(new, m * o + (1 - m) * on, atol=1e-7)


def test_full_update_moves_target_and_checkpoint_restores_it():
    agent = agent_for(["agent=atc", "agent.objective_params.atc.predictor_hidden=16"])
    before = snapshot(agent.backbone.objectives["atc"].target)
    metrics = agent.update(make_batch(), step=0)
    for key in ("atc_loss", "atc_acc", "curl_loss", "reward_loss", "aux_loss"):
        assert math.isfinite(metrics[key])
    after = snapshot(agent.backbone.objectives["atc"].target)
    assert any(not torch.equal(a, b) for a, b in zip(before, after))  # moved by after_update
    atc = agent.backbone.objectives["atc"]  # counted once, without the frozen target copies
    own = sum(p.numel() for p in atc.predictor.parameters()) + atc.W.numel()
    assert dict(agent.parameter_counts())["objective.atc"] == own
    restored = agent_for(["agent=atc", "agent.objective_params.atc.predictor_hidden=16"], seed=1)
    restored.load_state_dict(agent.state_dict())
    assert all(torch.equal(a, b) for a, b in zip(after, snapshot(restored.backbone.objectives["atc"].target)))
    restored.backbone.objectives["atc"].after_update()  # still tied to the restored agent's own encoder
    online = next(restored.backbone.encoder.parameters()).detach()
    first = next(restored.backbone.objectives["atc"].target.parameters()).detach()
    assert torch.allclose(first, 0.99 * after[0] + 0.01 * online, atol=1e-7)


# ----------------------------------------------------------------------------- configs


def test_agent_files_differ_from_taco_only_in_the_objectives():
    base = typed(compose(["agent=taco", "task=hopper_hop"])).agent
    expected = {"spr": {"spr", "curl", "reward"}, "atc": {"atc", "curl", "reward"},
                "driml": {"driml", "curl", "reward"}, "curl": {"curl"}}
    for name in NEW_AGENTS:
        agent = typed(compose([f"agent={name}", "task=hopper_hop"])).agent
        assert agent.name == name and agent.action_encoder
        assert {k for k, w in agent.objectives.items() if w} == expected[name]
        for field in ("lr", "feature_dim", "hidden_dim", "batch_size", "K", "nstep", "discount",
                      "critic_target_tau", "stddev_clip", "stddev_schedule", "latent_action_dim",
                      "latent_action_rounding", "action_hidden_dim", "reward_target"):
            assert getattr(agent, field) == getattr(base, field), (name, field)
    assert typed(compose(["agent=driml", "task=quadruped_run"])).agent.K == 1  # the N/A cells of Table 2


def test_agent_files_are_commented_and_match_code_defaults():
    taco_keys = set(yaml.safe_load((CONF_DIR / "agent" / "taco.yaml").read_text()))
    defaults = {"spr": dataclasses.asdict(SPRParams()), "atc": dataclasses.asdict(ATCParams())}  # the registered
    for name in NEW_AGENTS:
        text = (CONF_DIR / "agent" / f"{name}.yaml").read_text()
        for line in text.splitlines():
            assert not line.strip() or "#" in line, f"{name}.yaml: uncommented line {line!r}"
        data = yaml.safe_load(text)
        assert taco_keys <= set(data), name
        for obj, params in data.get("objective_params", {}).items():
            assert params == defaults[obj]


# ----------------------------------------------------------------------------- each agent file, one update
# (the training loop itself is exercised end to end by the session's tiny TACO run: tests/test_train_e2e.py)


@pytest.mark.parametrize("name", NEW_AGENTS)
def test_agent_file_builds_an_agent_whose_update_trains_its_objective(name: str):
    loss = {"spr": "spr_loss", "atc": "atc_loss", "driml": "driml_loss", "curl": "curl_loss"}[name]
    rc = typed(compose(["profile=tiny", f"agent={name}"]))
    assert rc.agent.name == name
    torch.manual_seed(0)
    agent = Agent(rc.agent, OBS, A)
    assert loss in agent.metric_names() and "aux_loss" in agent.metric_names()  # train.csv's columns
    objectives = {k: snapshot(m) for k, m in agent.backbone.objectives.items() if any(True for _ in m.parameters())}
    encoder = snapshot(agent.backbone.encoder)
    metrics = agent.update(make_batch(K=rc.agent.K), step=10)
    assert math.isfinite(metrics[loss]) and math.isfinite(metrics["aux_loss"]) and metrics[loss] != 0.0
    assert set(agent.metric_names()) <= set(metrics)
    for key, before in objectives.items():  # every objective with parameters took a step
        assert any(not torch.equal(b, p) for b, p in zip(before, agent.backbone.objectives[key].parameters())), key
    assert any(not torch.equal(b, p) for b, p in zip(encoder, agent.backbone.encoder.parameters()))
