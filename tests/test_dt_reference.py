"""The Decision Transformer as Chen et al.'s gym code builds it (kzl/decision-transformer, gym/experiment.py,
decision_transformer.py, trajectory_gpt2.py; issue 16 point 5). The known answers are GPT-2's equations
evaluated in float64 numpy and GPT-2's parameter count by hand, not the code under test."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from repro.config.compose import compose, typed
from repro.learners import build_learner, dt_model

OBS = (9, 16, 16)
A_DIM = 2
# Chen et al.'s gym model (gym/experiment.py: K 20, embed_dim 128, n_layer 3, n_head 1, dropout 0.1, max_ep_len
# 1000, activation_function relu; GPT-2's initialisation, no dropout after the activation), written out here
GYM = {"context": 20, "embed_dim": 128, "n_layers": 3, "n_heads": 1, "dropout": 0.1, "max_timestep": 1000,
       "activation": "relu", "init": "gpt2", "ff_dropout": False}


def model_of(**over: object) -> dt_model.DecisionTransformer:
    """The gym model with ``over`` replacing some of its values."""
    return dt_model.DecisionTransformer(OBS, A_DIM, **{**GYM, **over})


def sampler_of(episodes: list[dict[str, np.ndarray]], context: int) -> dt_model.SequenceSampler:
    """A window sampler as the gym code's get_batch (frame stacks of 3, returns-to-go / 1000, actions padded: -10)."""
    return dt_model.SequenceSampler(episodes, context=context, frame_stack=3, rtg_scale=1e-3, seed=0, action_pad=-10.0)


def gpt2_block_params(e: int) -> int:
    """ln_1 (2E) + c_attn (E x 3E + 3E) + c_proj (E x E + E) + ln_2 (2E) + c_fc (E x 4E + 4E) + mlp c_proj
    (4E x E + E) = 12 E^2 + 13 E."""
    return 2 * e + (3 * e * e + 3 * e) + (e * e + e) + 2 * e + (4 * e * e + 4 * e) + (4 * e * e + e)


def test_paper_size_model_has_the_gpt2_layout_and_parameter_count():
    e, layers = 128, 3
    rc = typed(compose(["agent=dt", "task=cheetah_run"]))
    assert (rc.agent.dt.activation, rc.agent.dt.init, rc.agent.dt.ff_dropout, rc.agent.dt.action_pad) == \
        ("relu", "gpt2", False, -10.0)
    torch.manual_seed(0)
    learner = build_learner(rc.agent, (9, 84, 84), 6, "cpu")
    body = learner.model.transformer
    assert [n for n, _ in body.named_children()] == ["h", "ln_f"] and len(body.h) == layers
    for block in body.h:
        assert [n for n, _ in block.named_children()] == ["ln_1", "attn", "resid_dropout", "ln_2", "mlp"]
        mlp = list(block.mlp.children())
        kinds = [type(m) for m in mlp if not isinstance(m, nn.Identity)]
        assert kinds == [nn.Linear, nn.ReLU, nn.Linear, nn.Dropout]  # no dropout after the activation
        assert block.attn.dropout == 0.1 and block.attn.num_heads == 1
        # GPT-2 has three dropouts per block: attention weights, attention residual, MLP residual
        assert sum(isinstance(m, nn.Dropout) for m in block.modules()) == 2 and block.attn.dropout > 0
    assert sum(p.numel() for p in body.parameters()) == layers * gpt2_block_params(e) + 2 * e == 595_072
    embeddings = [m for m in learner.model.modules() if isinstance(m, nn.Embedding)]
    assert embeddings == [learner.model.embed_timestep]  # no position embedding besides the timestep's
    assert tuple(learner.model.embed_timestep.weight.shape) == (1000, e)


def test_default_initialisation_is_gpt2s_on_the_body():
    torch.manual_seed(0)
    model = model_of()
    for block in model.transformer.h:
        for w in (block.attn.in_proj_weight, block.attn.out_proj.weight, block.mlp.c_fc.weight,
                  block.mlp.c_proj.weight):
            assert abs(w.detach().std().item() - 0.02) < 0.0015 and abs(w.detach().mean().item()) < 0.002
        for b in (block.attn.in_proj_bias, block.attn.out_proj.bias, block.mlp.c_fc.bias, block.mlp.c_proj.bias):
            assert not b.detach().any()
        for ln in (block.ln_1, block.ln_2):
            assert bool((ln.weight == 1).all()) and not ln.bias.detach().any()
    torch.manual_seed(0)
    legacy = model_of(init="torch")
    xavier = math.sqrt(2.0 / (128 + 3 * 128)) / math.sqrt(1.0)  # xavier_uniform std of the (3E, E) in_proj
    assert legacy.transformer.h[0].attn.in_proj_weight.std().item() == pytest.approx(xavier, rel=0.05)
    with pytest.raises(ValueError, match="dt.init"):
        model_of(init="xavier")


def _layer_norm(x: np.ndarray, w: np.ndarray, b: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + eps) * w + b


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().double().numpy()


def gpt2_reference(x: np.ndarray, body, n_heads: int, act) -> np.ndarray:
    """trajectory_gpt2.GPT2Model without dropout: per block a = x + c_proj(attn(ln_1(x))), causal softmax of
    q k^T / sqrt(d) (masked scores -1e4 as GPT-2), then a + c_proj(act(c_fc(ln_2(a)))); ln_f at the end."""
    batch, n, e = x.shape
    d = e // n_heads
    causal = np.tril(np.ones((n, n), dtype=bool))
    for block in body.h:
        y = _layer_norm(x, _np(block.ln_1.weight), _np(block.ln_1.bias))
        qkv = y @ _np(block.attn.in_proj_weight).T + _np(block.attn.in_proj_bias)
        q, k, v = (qkv[..., i * e:(i + 1) * e].reshape(batch, n, n_heads, d).transpose(0, 2, 1, 3) for i in range(3))
        w = q @ k.transpose(0, 1, 3, 2) / math.sqrt(d)
        w = np.where(causal, w, -1e4)
        w = np.exp(w - w.max(-1, keepdims=True))
        w /= w.sum(-1, keepdims=True)
        a = (w @ v).transpose(0, 2, 1, 3).reshape(batch, n, e)
        x = x + a @ _np(block.attn.out_proj.weight).T + _np(block.attn.out_proj.bias)
        y = _layer_norm(x, _np(block.ln_2.weight), _np(block.ln_2.bias))
        hidden = act(y @ _np(block.mlp.c_fc.weight).T + _np(block.mlp.c_fc.bias))
        x = x + hidden @ _np(block.mlp.c_proj.weight).T + _np(block.mlp.c_proj.bias)
    return _layer_norm(x, _np(body.ln_f.weight), _np(body.ln_f.bias))


@pytest.mark.parametrize("activation", ["relu", "gelu"])
def test_body_equals_gpt2_equations_in_float64(activation: str):
    torch.manual_seed(1)
    model = model_of(context=4, embed_dim=16, n_layers=2, n_heads=2, activation=activation).double().eval()
    with torch.no_grad():  # random LayerNorm affine parameters, so they are exercised too
        for m in model.transformer.modules():
            if isinstance(m, nn.LayerNorm):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.2, 0.2)
    x = torch.randn(3, 12, 16, dtype=torch.float64)
    mask = model.attention_mask(torch.ones(3, 4, dtype=torch.bool))
    with torch.no_grad():
        out = model.transformer(x, mask).numpy()
    acts = {"relu": lambda z: np.maximum(z, 0.0),
            "gelu": lambda z: 0.5 * z * (1.0 + np.vectorize(math.erf)(z / math.sqrt(2.0)))}
    expected = gpt2_reference(x.numpy(), model.transformer, 2, acts[activation])
    np.testing.assert_allclose(out, expected, rtol=1e-10, atol=1e-10)


def test_corl_and_torch_layer_switches():
    model = model_of(embed_dim=16, n_layers=1, activation="gelu", ff_dropout=True)
    mlp = model.transformer.h[0].mlp
    assert [type(m) for m in mlp.children()] == [nn.Linear, nn.GELU, nn.Dropout, nn.Linear, nn.Dropout]
    with pytest.raises(ValueError, match="dt.activation"):
        model_of(activation="swish")


def _episode(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"frames": rng.integers(0, 256, (n + 1, 3, 16, 16), dtype=np.uint8),
            "actions": rng.uniform(-1, 1, (n, A_DIM)).astype(np.float32),
            "rewards": rng.uniform(0, 1, n).astype(np.float32)}


def test_training_windows_pad_actions_with_minus_10_and_padding_never_reaches_a_real_step():
    sampler = sampler_of([_episode(6)], context=5)
    w = sampler.window(0, 3)  # 3 real steps, 2 padded on the left
    assert w["mask"].tolist() == [False, False, True, True, True]
    assert (w["actions"][:2] == -10.0).all() and not w["rtg"][:2].any() and not w["timesteps"][:2].any()
    assert not w["frames"][:2].any()
    torch.manual_seed(0)
    model = model_of(context=5, embed_dim=16, n_layers=2, n_heads=2).double().eval()

    def predict(window: dict[str, np.ndarray]) -> torch.Tensor:
        x = dt_model.batch_to_tensors({k: v[None] for k, v in window.items()})
        with torch.no_grad():
            return model(x["frames"], x["actions"], x["rtg"], x["timesteps"], x["mask"])[0]

    zero_pad = dict(w, actions=np.where(w["mask"][:, None], w["actions"], 0.0).astype(np.float32))
    assert torch.equal(predict(w)[2:], predict(zero_pad)[2:])  # the -10 (or 0) pad is masked out
    # no position embedding: the same 3 steps unpadded give the same predictions (only timesteps position them)
    short = sampler_of([_episode(6)], context=3).window(0, 3)
    torch.testing.assert_close(predict(short), predict(w)[2:], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("override", ["agent.dt.activation=swish", "agent.dt.init=xavier"])
def test_bad_dt_switch_is_one_line_config_error(override: str):
    from repro.config.compose import ConfigError

    with pytest.raises(ConfigError, match=override.split("=")[0] + ".* is not one of") as err:
        compose(["agent=dt", "task=cheetah_run", override])
    assert "\n" not in str(err.value)
