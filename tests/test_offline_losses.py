"""Offline losses: float64 known answers transcribed from the papers' equations (plain python loops, not the
code under test), gradient paths, and the Decision Transformer's masks and sequence sampler."""

from __future__ import annotations

import dataclasses
import inspect
import math

import numpy as np
import pytest
import torch

from repro.config import paper_defaults
from repro.config.schema import CQLConfig, DTConfig, IQLConfig, TD3BCConfig
from repro.learners import dt_model
from repro.learners.losses import cql, dt, iql, td3bc

F64 = torch.float64


def t64(values) -> torch.Tensor:
    return torch.tensor(values, dtype=F64)


def leaf(values) -> torch.Tensor:
    return t64(values).requires_grad_(True)


# ---------------------------------------------------------------- TD3+BC (Fujimoto & Gu 2021, eq. 5)

Q1 = [[1.5], [-2.0], [0.25]]
Q2 = [[0.5], [-1.0], [3.0]]
PI = [[0.2, -0.4], [0.9, 0.1], [-0.3, 0.6]]
DATA_A = [[0.0, -0.5], [1.0, 0.3], [-0.1, 0.2]]


def td3bc_reference(q1, q2, pi, a, alpha, use_min):
    q = [min(x[0], y[0]) if use_min else x[0] for x, y in zip(q1, q2)]
    n = len(q)
    lam = alpha / (sum(abs(v) for v in q) / n)
    bc = sum((p - b) ** 2 for pr, ar in zip(pi, a) for p, b in zip(pr, ar)) / (n * len(pi[0]))
    return -lam * sum(q) / n + bc, lam, bc, sum(q) / n


@pytest.mark.parametrize("lambda_from", ["min", "q1"])
def test_td3bc_known_answer(lambda_from):
    loss, m = td3bc.actor_loss(t64(Q1), t64(Q2), t64(PI), t64(DATA_A), alpha=2.5, lambda_from=lambda_from)
    ref, lam, bc, q = td3bc_reference(Q1, Q2, PI, DATA_A, 2.5, lambda_from == "min")
    assert loss.item() == pytest.approx(ref, rel=1e-12)
    assert (m["actor_lambda"], m["actor_bc"], m["actor_q"]) == pytest.approx((lam, bc, q), rel=1e-12)


def test_td3bc_lambda_detached_and_no_grad_into_data_actions():
    q1, q2, pi, a = leaf(Q1), leaf(Q2), leaf(PI), leaf(DATA_A)
    loss, m = td3bc.actor_loss(q1, q2, pi, a, alpha=2.5, lambda_from="min")
    loss.backward()
    n, lam = 3, m["actor_lambda"]
    # lambda a constant: d loss / d Q_b = -lambda / B for the head that is the min, 0 for the other
    assert q1.grad.flatten().tolist() == pytest.approx([0.0, -lam / n, -lam / n], rel=1e-12)
    assert q2.grad.flatten().tolist() == pytest.approx([-lam / n, 0.0, 0.0], rel=1e-12)
    expected_pi = [[2 * (p - b) / (n * 2) for p, b in zip(pr, ar)] for pr, ar in zip(PI, DATA_A)]
    assert pi.grad.tolist() == [pytest.approx(row, rel=1e-12) for row in expected_pi]
    assert a.grad is None


def test_td3bc_rejects_bad_input():
    with pytest.raises(ValueError, match="shape mismatch"):
        td3bc.actor_loss(t64(Q1), t64(Q2).flatten(), t64(PI), t64(DATA_A), alpha=2.5, lambda_from="min")
    with pytest.raises(ValueError, match="lambda_from"):
        td3bc.actor_loss(t64(Q1), t64(Q2), t64(PI), t64(DATA_A), alpha=2.5, lambda_from="q2")


# ---------------------------------------------------------------- CQL (Kumar et al. 2020, eq. 4 / appendix F)

QD = [0.5, -1.0]
QU = [[0.1, 0.7, -0.2], [1.5, -0.5, 0.0]]
QP = [[0.9, 1.2, 0.4], [-0.3, 0.2, 2.0]]
QNP = [[0.0, -1.1, 0.6], [0.8, 0.8, -2.2]]
LP = [[-1.0, 0.5, -0.2], [0.3, -2.0, 1.0]]
LNP = [[0.1, -0.7, -1.5], [0.0, 0.4, -0.9]]


def cql_reference(qd, qu, qp, qnp, alpha, temp, is_=False, lp=None, lnp=None, action_dim=None, with_data=False):
    lses = []
    for b in range(len(qd)):
        xs = []
        for j in range(len(qu[b])):
            if is_:
                xs += [qu[b][j] - math.log(0.5 ** action_dim), qp[b][j] - lp[b][j], qnp[b][j] - lnp[b][j]]
            else:
                xs += [qu[b][j], qp[b][j], qnp[b][j]]
        if with_data:
            xs.append(qd[b])
        lses.append(temp * math.log(sum(math.exp(x / temp) for x in xs)))
    return alpha * (sum(lses) / len(lses) - sum(qd) / len(qd)), sum(lses) / len(lses)


@pytest.mark.parametrize("temp", [1.0, 0.5])
@pytest.mark.parametrize("mode", ["plain", "is", "with_data"])
def test_cql_regulariser_known_answer(temp, mode):
    kw: dict = {"importance_sampling": False}
    if mode == "is":
        kw = {
            "importance_sampling": True,
            "action_dim": 3,
            "log_prob_policy": t64(LP),
            "log_prob_next_policy": t64(LNP),
        }
    reg, parts = cql.regulariser(t64(QD), t64(QU), t64(QP), t64(QNP), alpha=2.0, temperature=temp,
                                 include_data_in_logsumexp=mode == "with_data", **kw)
    ref, lse = cql_reference(QD, QU, QP, QNP, 2.0, temp, is_=mode == "is", lp=LP, lnp=LNP, action_dim=3,
                             with_data=mode == "with_data")
    assert reg.item() == pytest.approx(ref, rel=1e-12)
    assert parts["lse"].item() == pytest.approx(lse, rel=1e-12)
    assert parts["q_data"].item() == pytest.approx(sum(QD) / 2, rel=1e-12)


def test_cql_uniform_density():
    assert cql.uniform_log_density(6) == pytest.approx(math.log(0.5 ** 6), rel=1e-12)
    u = cql.uniform_actions(500, 4, 3, like=torch.zeros((), dtype=F64), generator=torch.Generator().manual_seed(0))
    assert u.shape == (500, 4, 3) and u.dtype == F64
    assert -1.0 <= u.min().item() < -0.95 and 0.95 < u.max().item() <= 1.0


class LinearCritic(torch.nn.Module):
    """Q_i(h, a) = h . w_i + a . v_i, known in closed form."""

    def __init__(self):
        super().__init__()
        self.w = torch.nn.Parameter(t64([[0.5, -1.0], [0.25, 2.0]]))  # (heads, R)
        self.v = torch.nn.Parameter(t64([[1.0, -0.5], [-2.0, 0.75]]))  # (heads, A)

    def forward(self, h, a):
        return tuple((h @ self.w[i] + a @ self.v[i]).unsqueeze(-1) for i in range(2))


def test_cql_critic_regularisers_match_per_state_evaluation():
    """Each sample is evaluated at its own state: a repeat instead of repeat_interleave would fail here."""
    gen = torch.Generator().manual_seed(1)
    B, N, R, A = 3, 2, 2, 2
    h = torch.randn(B, R, generator=gen, dtype=F64)
    acts = [torch.rand(B, N, A, generator=gen, dtype=F64) * 2 - 1 for _ in range(3)]
    critic = LinearCritic()
    w, v = critic.w.tolist(), critic.v.tolist()
    data_a = torch.rand(B, A, generator=gen, dtype=F64)
    q_data = critic(h, data_a)
    regs, metrics = cql.critic_regularisers(critic, h, q_data, *acts, alpha=1.5, temperature=1.0,
                                            importance_sampling=False, include_data_in_logsumexp=False)
    for i in range(2):
        def q(b, act, i=i):
            return sum(h[b, r].item() * w[i][r] for r in range(R)) + sum(act[k] * v[i][k] for k in range(A))
        qs = [[[q(b, s[b, j].tolist()) for j in range(N)] for b in range(B)] for s in acts]
        qd = [q(b, data_a[b].tolist()) for b in range(B)]
        ref, lse = cql_reference(qd, *qs, alpha=1.5, temp=1.0)
        assert regs[i].item() == pytest.approx(ref, rel=1e-12)
        assert metrics[f"cql_reg_q{i + 1}"] == pytest.approx(ref, rel=1e-12)
        assert metrics[f"cql_lse_q{i + 1}"] == pytest.approx(lse, rel=1e-12)
        assert metrics[f"cql_q_data_q{i + 1}"] == pytest.approx(sum(qd) / B, rel=1e-12)
        assert metrics[f"cql_q_uniform_q{i + 1}"] == pytest.approx(np.mean(qs[0]), rel=1e-12)


@pytest.mark.parametrize("importance_sampling", [False, True])
def test_cql_policy_samples_carry_no_gradient(importance_sampling):
    """Even if the caller forgets torch.no_grad(), the regulariser must not train the actor."""
    gen = torch.Generator().manual_seed(2)
    B, N, R, A = 4, 3, 2, 2
    h = torch.randn(B, R, generator=gen, dtype=F64).requires_grad_(True)
    actor = torch.nn.Linear(R, A).double()
    policy = torch.tanh(actor(h)).unsqueeze(1).expand(B, N, A) + 0.0
    next_policy = torch.tanh(actor(h + 1.0)).unsqueeze(1).expand(B, N, A) + 0.0
    log_prob = actor(h).sum(-1, keepdim=True).expand(B, N) + 0.0  # depends on the actor, must be cut too
    critic = LinearCritic()
    q_data = critic(h, torch.zeros(B, A, dtype=F64))
    kw = {"log_prob_policy": log_prob, "log_prob_next_policy": log_prob} if importance_sampling else {}
    regs, _ = cql.critic_regularisers(critic, h, q_data, cql.uniform_actions(B, N, A, like=h), policy,
                                      next_policy, alpha=1.0, temperature=1.0,
                                      importance_sampling=importance_sampling, include_data_in_logsumexp=False,
                                      **kw)
    sum(regs).backward()
    assert actor.weight.grad is None and actor.bias.grad is None
    assert critic.v.grad is not None and critic.v.grad.abs().sum() > 0
    assert h.grad is not None  # the encoder is trained by the regulariser through h


def test_cql_regulariser_gradient_is_softmax_minus_data():
    """d R / d x_bj = alpha softmax_j(x_b / T) / B and d R / d Q(data)_b = -alpha / B."""
    qd, qu, qp, qnp = leaf(QD), leaf(QU), leaf(QP), leaf(QNP)
    reg, _ = cql.regulariser(qd, qu, qp, qnp, alpha=2.0, temperature=0.5, importance_sampling=False,
                             include_data_in_logsumexp=False)
    reg.backward()
    for b in range(2):
        xs = QU[b] + QP[b] + QNP[b]
        z = sum(math.exp(x / 0.5) for x in xs)
        assert qu.grad[b].tolist() == pytest.approx([2.0 * math.exp(x / 0.5) / z / 2 for x in QU[b]], rel=1e-10)
    assert qd.grad.tolist() == pytest.approx([-1.0, -1.0], rel=1e-12)


def test_cql_rejects_bad_input():
    with pytest.raises(ValueError, match="importance sampling needs"):
        cql.regulariser(t64(QD), t64(QU), t64(QP), t64(QNP), 1.0, 1.0, importance_sampling=True,
                        include_data_in_logsumexp=False)
    with pytest.raises(ValueError, match="q_data must be"):
        cql.regulariser(t64(QD).unsqueeze(1), t64(QU), t64(QP), t64(QNP), 1.0, 1.0, importance_sampling=False,
                        include_data_in_logsumexp=False)


def test_cql_alpha_table_6():
    # Table 6 of the TACO paper (facts, typed here independently of the packaged CSV)
    assert paper_defaults.cql_alpha("hopper_hop", "full-replay") == 2.0
    assert paper_defaults.cql_alpha("cheetah_run", "medium_replay") == 2.0
    assert paper_defaults.cql_alpha("walker_run", "medium-replay") == 1.0
    assert paper_defaults.cql_alpha("quadruped_run", "full_replay") == 4.0
    tasks = ["hopper_hop", "cheetah_run", "walker_run", "quadruped_run"]
    assert all(paper_defaults.cql_alpha(t, "medium") == 0.5 for t in tasks)
    with pytest.raises(ValueError) as err:
        paper_defaults.cql_alpha("walker_walk", "medium")
    assert "\n" not in str(err.value) and "walker_walk" in str(err.value)
    with pytest.raises(ValueError):
        paper_defaults.cql_alpha("walker_run", "expert")


# ---------------------------------------------------------------- IQL (Kostrikov et al. 2022, eqs. 5, 6, 7)

TQ1 = [1.0, -0.5, 2.0, 0.3]
TQ2 = [0.8, -0.2, 2.5, -0.1]
V = [0.5, 0.1, 1.9, 0.4]


def test_iql_value_loss_known_answer_and_gradient():
    tq1, tq2, v = leaf(TQ1), leaf(TQ2), leaf(V)
    loss, _ = iql.value_loss(tq1, tq2, v, expectile=0.7)
    ds = [min(a, b) - c for a, b, c in zip(TQ1, TQ2, V)]
    weights = [abs(0.7 - (1.0 if d < 0 else 0.0)) for d in ds]
    assert sorted(weights) == pytest.approx([0.3, 0.3, 0.7, 0.7])  # the input exercises both sides
    assert loss.item() == pytest.approx(sum(w * d * d for w, d in zip(weights, ds)) / 4, rel=1e-12)
    loss.backward()
    assert tq1.grad is None and tq2.grad is None  # the target critic is never trained by V's loss
    assert v.grad.tolist() == pytest.approx([-2 * w * d / 4 for w, d in zip(weights, ds)], rel=1e-12)


def test_iql_critic_target_and_loss():
    r, disc, next_v = t64([1.0, 0.0, -0.5]), t64([0.99, 0.0, 0.9801]), leaf([2.0, 5.0, -1.0])
    target = iql.critic_target(r, disc, next_v)
    assert target.tolist() == pytest.approx([1.0 + 0.99 * 2.0, 0.0, -0.5 - 0.9801], rel=1e-12)
    assert not target.requires_grad
    q1, q2 = leaf([2.5, 0.5, -1.0]), leaf([3.0, -0.5, -2.0])
    loss, _ = iql.critic_loss(q1, q2, target)
    tl = target.tolist()
    ref = (
        sum((a - t) ** 2 for a, t in zip(q1.tolist(), tl)) / 3 + sum((b - t) ** 2 for b, t in zip(q2.tolist(), tl)) / 3
    )
    assert loss.item() == pytest.approx(ref, rel=1e-12)
    loss.backward()
    assert next_v.grad is None


@pytest.mark.parametrize("beta", [0.1, 3.0])
def test_iql_actor_loss_known_answer_clip_and_gradient(beta):
    tq1, tq2, v = leaf(TQ1 + [20.0]), leaf(TQ2 + [25.0]), leaf(V + [0.0])  # last: exp(beta * 20) > 100 at beta 3
    log_prob = leaf([-1.0, -2.5, 0.3, -0.7, -1.2])
    loss, _ = iql.actor_loss(log_prob, tq1, tq2, v, beta=beta, max_weight=100.0)
    advs = [min(a, b) - c for a, b, c in zip(tq1.tolist(), tq2.tolist(), v.tolist())]
    ws = [min(math.exp(beta * adv), 100.0) for adv in advs]
    assert (ws[-1] == 100.0) == (beta == 3.0)
    assert loss.item() == pytest.approx(-sum(w * lp for w, lp in zip(ws, log_prob.tolist())) / 5, rel=1e-12)
    loss.backward()
    assert tq1.grad is None and tq2.grad is None and v.grad is None
    assert log_prob.grad.tolist() == pytest.approx([-w / 5 for w in ws], rel=1e-12)


# ---------------------------------------------------------------- Decision Transformer (Chen et al. 2021)

OBS = (9, 16, 16)
A_DIM = 2


def tiny_dt(context: int = 5) -> dt_model.DecisionTransformer:
    torch.manual_seed(0)
    model = dt_model.DecisionTransformer(OBS, A_DIM, context=context, embed_dim=16, n_layers=2, n_heads=2,
                                   dropout=0.1, max_timestep=50, activation="relu", init="gpt2",
                                   ff_dropout=False).double()
    return model.eval()


def dt_inputs(batch: int = 2, steps: int = 5, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return {"frames": torch.randint(0, 256, (batch, steps) + OBS, generator=g).to(torch.uint8),
            "actions": torch.rand(batch, steps, A_DIM, generator=g, dtype=F64) * 2 - 1,
            "rtg": torch.rand(batch, steps, 1, generator=g, dtype=F64),
            "timesteps": torch.arange(3, 3 + steps).repeat(batch, 1),
            "mask": torch.ones(batch, steps, dtype=torch.bool)}


def run(model, x):
    with torch.no_grad():
        return model(x["frames"], x["actions"], x["rtg"], x["timesteps"], x["mask"])


def changed(x, key, step, value=None):
    y = {k: v.clone() for k, v in x.items()}
    if key == "frames":
        y[key][:, step] = 255 - y[key][:, step]
    else:
        y[key][:, step] = value if value is not None else y[key][:, step] + 0.7
    return y


def test_dt_attention_mask_known_answer():
    model = tiny_dt()
    mask = torch.tensor([[False, True, True]])
    blocked = model.attention_mask(mask)
    assert blocked.shape == (2, 9, 9)  # one copy per head
    for i in range(9):
        for j in range(9):
            allowed = j <= i and (j // 3 >= 1 or j == i)
            assert bool(blocked[0, i, j]) == (not allowed) and bool(blocked[1, i, j]) == (not allowed)


def test_dt_token_layout_known_answer():
    r, s, a = (torch.tensor([[[10 * k + t] for t in range(3)]]) for k in (1, 2, 3))  # (1, 3, 1) tags
    assert dt_model.interleave(r, s, a).flatten().tolist() == [10, 20, 30, 11, 21, 31, 12, 22, 32]


def test_dt_causal_and_token_order():
    """Prediction t sees R_<=t, s_<=t, a_<t: the (R, s, a) order within a step and the causal mask."""
    model, x = tiny_dt(), dt_inputs()
    base = run(model, x)
    t = 2
    for key in ["frames", "rtg", "actions"]:
        out = run(model, changed(x, key, t))
        assert torch.equal(out[:, :t], base[:, :t]), f"a later {key} changed an earlier prediction"
        assert not torch.allclose(out[:, t + 1:], base[:, t + 1:]), f"{key} at t does not reach t+1"
        if key == "actions":
            assert torch.equal(out[:, t], base[:, t]), "a_t leaked into its own prediction"
        else:
            assert not torch.allclose(out[:, t], base[:, t]), f"{key}_t does not reach the prediction at t"
    # the timestep embedding is used
    out = run(model, changed(x, "timesteps", t, value=40))
    assert not torch.allclose(out[:, t], base[:, t])


def test_dt_padding_does_not_influence_real_steps():
    model, x = tiny_dt(), dt_inputs()
    x["mask"][0, :2] = False  # row 0: two left-padded steps
    base = run(model, x)
    y = x
    for key in ["frames", "rtg", "actions"]:
        for step in (0, 1):
            y = changed(y, key, step)
    y = changed(y, "timesteps", 0, value=0)
    out = run(model, y)
    assert torch.equal(out[0, 2:], base[0, 2:])
    assert not torch.allclose(out[1, :2], base[1, :2])  # row 1 has no padding: the same change is seen there
    # the same three steps unpadded in a shorter window give the same predictions
    short = {k: v[:1, 2:] for k, v in x.items()}
    assert torch.allclose(run(model, short)[0], base[0, 2:], rtol=1e-12, atol=1e-12)


def test_dt_training_mode_has_no_nan_with_padding():
    model, x = tiny_dt(), dt_inputs()
    model.train()
    x["mask"][:, :4] = False
    pred = model(x["frames"], x["actions"], x["rtg"], x["timesteps"], x["mask"])
    loss = dt.action_loss(pred, x["actions"], torch.as_tensor(dt_model.kept_steps(x["mask"].numpy())))
    loss.backward()
    assert torch.isfinite(pred).all() and all(torch.isfinite(p.grad).all() for p in model.parameters()
                                              if p.grad is not None)


def test_dt_action_loss_known_answer_and_mask():
    pred = leaf([[[0.1, 0.2], [0.5, -0.5], [1.0, 0.0]]])
    target = leaf([[[9.0, 9.0], [0.0, 0.0], [0.5, 0.5]]])
    keep = torch.as_tensor(dt_model.kept_steps(np.array([[False, True, True]])))
    assert keep.tolist() == [1, 2] and keep.dtype == torch.int64
    loss = dt.action_loss(pred, target, keep)
    ref = ((0.5 ** 2 + 0.5 ** 2) + (0.5 ** 2 + 0.5 ** 2)) / 4
    assert loss.item() == pytest.approx(ref, rel=1e-12)
    loss.backward()
    assert pred.grad[0, 0].tolist() == [0.0, 0.0] and target.grad is None
    with pytest.raises(ValueError, match="int64 step indices"):
        dt.action_loss(pred, target, torch.tensor([[False, True, True]]))  # the boolean mask is not the index


def test_dt_action_loss_by_index_is_the_boolean_mask_loss_bit_for_bit():
    """Gathering the kept steps by their flat indices picks what indexing with the mask picks, in its order:
    the loss and every gradient are the same bits (float32, as the learner trains)."""
    rng = np.random.default_rng(4)
    mask = rng.random((6, 5)) < 0.6
    mask[:, -1] = True  # a window always ends on a real step
    pred = torch.tensor(rng.normal(size=(6, 5, 3)), dtype=torch.float32, requires_grad=True)
    target = torch.tensor(rng.normal(size=(6, 5, 3)), dtype=torch.float32)
    by_mask = (pred[torch.as_tensor(mask)] - target[torch.as_tensor(mask)]).pow(2).mean()
    (grad_mask,) = torch.autograd.grad(by_mask, pred)
    by_index = dt.action_loss(pred, target, torch.as_tensor(dt_model.kept_steps(mask)))
    (grad_index,) = torch.autograd.grad(by_index, pred)
    assert by_index.view(torch.int32).item() == by_mask.view(torch.int32).item()
    assert torch.equal(grad_index.view(torch.int32), grad_mask.view(torch.int32))


def test_returns_to_go():
    rewards = np.array([1.0, 0.5, 2.0, 0.25], dtype=np.float32)
    ref = [sum(rewards[t:].tolist()) for t in range(4)]
    assert dt_model.returns_to_go(rewards).tolist() == pytest.approx(ref, rel=1e-12)


def tagged_episodes(lengths):
    """Frame t of episode e has pixel (0,0,0) = e and (0,0,1) = t; action t is (e, t); reward t = 10 e + t."""
    eps = []
    for e, n in enumerate(lengths):
        frames = np.zeros((n + 1, 3, 4, 4), dtype=np.uint8)
        frames[:, 0, 0, 0], frames[:, 0, 0, 1] = e, np.arange(n + 1)
        actions = np.stack([np.full(n, e), np.arange(n)], 1).astype(np.float32)
        eps.append({"frames": frames, "actions": actions, "rewards": (10.0 * e + np.arange(n)).astype(np.float32)})
    return eps


def test_sequence_sampler_windows_never_cross_and_pad_left():
    lengths, K, fs = [7, 3, 12], 5, 3
    eps = tagged_episodes(lengths)
    sampler = dt_model.SequenceSampler(eps, context=K, frame_stack=fs, rtg_scale=1e-3, seed=0, action_pad=-10.0)
    batch = sampler.sample(400)
    assert batch["frames"].shape == (400, K, 3 * fs, 4, 4) and batch["frames"].dtype == np.uint8
    starts_seen = set()
    for i in range(400):
        e, s = int(batch["episode"][i]), int(batch["start"][i])
        starts_seen.add((e, s))
        n_real = min(K, lengths[e] - s)
        mask = batch["mask"][i]
        assert mask.tolist() == [False] * (K - n_real) + [True] * n_real
        for k in range(K):
            if not mask[k]:
                assert not batch["frames"][i, k].any() and (batch["actions"][i, k] == -10).all()  # Chen et al.: -10
                assert batch["rtg"][i, k, 0] == 0 and batch["timesteps"][i, k] == 0
                continue
            t = s + k - (K - n_real)
            assert batch["actions"][i, k].tolist() == [e, t]  # same episode, consecutive steps
            assert batch["timesteps"][i, k] == t
            for f in range(fs):  # oldest first, the first frame repeated before the start
                assert batch["frames"][i, k, 3 * f, 0, 0] == e
                assert batch["frames"][i, k, 3 * f, 0, 1] == max(t - (fs - 1 - f), 0)
            rtg = sum(10.0 * e + u for u in range(t, lengths[e])) / 1000
            assert batch["rtg"][i, k, 0] == pytest.approx(rtg, rel=1e-6)
    # the loss's step indices: the real steps of the flattened (B*K) windows, ascending
    steps = [(i, k) for i in range(400) for k in range(K) if batch["mask"][i, k]]
    assert batch["keep"].dtype == np.int64 and batch["keep"].tolist() == [i * K + k for i, k in steps]
    assert starts_seen == {(e, s) for e, n in enumerate(lengths) for s in range(n)}  # every start reachable


def test_sequence_sampler_state_and_bad_episodes():
    eps = tagged_episodes([6, 4])
    kw = {"context": 3, "frame_stack": 3, "rtg_scale": 1e-3, "action_pad": -10.0}
    a = dt_model.SequenceSampler(eps, seed=5, **kw)
    a.sample(3)
    b = dt_model.SequenceSampler(eps, seed=99, **kw)
    b.load_state_dict(a.state_dict())
    assert np.array_equal(a.sample(8)["start"], b.sample(8)["start"])
    bad = dict(eps[0], frames=eps[0]["frames"][:-1])  # frames must be T+1
    with pytest.raises(ValueError, match="episode 0"):
        dt_model.SequenceSampler([bad], seed=0, **kw)
    with pytest.raises(ValueError, match="no episodes"):
        dt_model.SequenceSampler([], seed=0, **kw)
    with pytest.raises(ValueError, match="timestep embedding"):
        dt_model.SequenceSampler(eps, seed=0, max_timestep=5, **kw)
    dt_model.SequenceSampler(eps, seed=0, max_timestep=6, **kw)


def test_config_values_have_one_source_the_loss_functions_repeat_none():
    """A config value (agent.td3bc, agent.cql, agent.iql, agent.dt) is a required argument of the function that
    uses it, never a keyword default beside the YAML's: a default here could drift from the config unseen."""
    def defaults(fn):
        return {k: p.default for k, p in inspect.signature(fn).parameters.items() if p.default is not p.empty}

    def config_fields(*configs):
        return {f.name for c in configs for f in dataclasses.fields(c)}

    config_names = config_fields(TD3BCConfig, CQLConfig, IQLConfig, DTConfig) | {"frame_stack", "seed"}
    functions = [td3bc.actor_loss, cql.regulariser, cql.critic_regularisers, iql.value_loss, iql.actor_loss,
                 dt_model.DecisionTransformer.__init__, dt_model.SequenceSampler.__init__,
                 dt_model.EvalContext.__init__, dt_model.make_optimizer, dt_model.GPT2Stack.__init__]
    repeated = {fn.__qualname__: sorted(set(defaults(fn)) & config_names) for fn in functions}
    # the sampler's max_timestep=None switches its length check off; it is not the config's value (1000)
    assert repeated == {fn.__qualname__: (["max_timestep"] if fn is dt_model.SequenceSampler.__init__ else [])
                        for fn in functions}
    assert defaults(dt_model.SequenceSampler.__init__)["max_timestep"] is None
    assert not hasattr(dt, "GRAD_CLIP")  # the clip is agent.dt.grad_clip alone


def test_eval_context_history():
    ctx = dt_model.EvalContext(target_return=500.0, context=3, rtg_scale=1e-3)
    obs = [np.full((9, 2, 2), i, dtype=np.uint8) for i in range(5)]
    first = ctx.inputs(obs[0], action_dim=2)
    assert first["mask"].tolist() == [False, False, True] and first["rtg"][-1, 0] == pytest.approx(0.5)
    ctx.record(np.array([0.1, 0.2]), reward=100.0)
    for i in range(1, 4):
        x = ctx.inputs(obs[i], action_dim=2)
        ctx.record(np.array([i, -i]), reward=10.0)
    # x is the window of steps 1, 2, 3; its action slot at step 3 is the zero placeholder
    assert x["mask"].all() and x["timesteps"].tolist() == [1, 2, 3]
    assert [int(f[0, 0, 0]) for f in x["frames"]] == [1, 2, 3]
    assert x["actions"].tolist() == [[1, -1], [2, -2], [0, 0]]
    assert x["rtg"][:, 0].tolist() == pytest.approx([0.4, 0.39, 0.38], rel=1e-6)
    ctx.inputs(obs[4], 2)
    with pytest.raises(RuntimeError):  # a second observation before record() is a caller bug
        ctx.inputs(obs[4], 2)


def test_dt_optimizer_warmup_and_weight_decay():
    model = torch.nn.Linear(2, 2)
    opt, sched = dt_model.make_optimizer(model, lr=1e-4, weight_decay=1e-4, warmup_steps=10)
    assert opt.param_groups[0]["weight_decay"] == 1e-4
    lrs = []
    for _ in range(12):
        lrs.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    assert lrs[0] == pytest.approx(1e-5) and lrs[4] == pytest.approx(5e-5) and lrs[9:] == pytest.approx([1e-4] * 3)


def test_dt_sampler_batch_feeds_the_model():
    eps = tagged_episodes([8, 3])
    for ep in eps:
        ep["frames"] = np.repeat(np.repeat(ep["frames"], 4, axis=2), 4, axis=3)  # 16x16
    sampler = dt_model.SequenceSampler(eps, context=5, frame_stack=3, rtg_scale=1e-3, seed=0, action_pad=-10.0)
    model = tiny_dt()
    b = dt_model.batch_to_tensors(sampler.sample(4))
    pred = model(b["frames"], b["actions"], b["rtg"], b["timesteps"], b["mask"])
    assert pred.shape == (4, 5, A_DIM) and torch.isfinite(pred).all()
