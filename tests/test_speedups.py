"""Opt-in speedups (agent.compile, agent.amp) against the plain path on the same weights and batch.

Weights alone say little after one update: each Adam optimizer's first step moves an entry by about
lr * sign(gradient) (lr 1e-4), whatever the gradient's size. So the tests compare what the update
did: the change of the encoder's weights (relative to its own size) and the encoder's last gradient
(the auxiliary step's), after checking that the weights moved at all.
"""

from __future__ import annotations

import pytest
import torch

from helpers import OBS, make_batch
from repro.agent.agent import Agent
from repro.config.compose import compose, typed

LR = 1e-4  # agent.lr of the default (taco) agent


def run_update(flags: list[str]) -> tuple[dict, torch.Tensor, torch.Tensor]:
    """One update from fixed weights and batch: (metrics, encoder weight change, encoder gradient), flattened."""
    rc = typed(compose(["agent.hidden_dim=64"] + flags))
    assert rc.agent.lr == LR
    torch.manual_seed(0)
    agent = Agent(rc.agent, OBS, 4)
    before = torch.cat([p.detach().flatten().clone() for p in agent.backbone.encoder.parameters()])
    torch.manual_seed(1)
    metrics = agent.update(make_batch(B=8), step=100)
    after = torch.cat([p.detach().flatten() for p in agent.backbone.encoder.parameters()])
    grad = torch.cat([p.grad.flatten() for p in agent.backbone.encoder.parameters()])
    return metrics, after - before, grad


def relative_error(x: torch.Tensor, ref: torch.Tensor) -> float:
    return float((x - ref).norm() / ref.norm())


def test_plain_update_moves_the_encoder_by_two_adam_steps():
    _, delta, grad = run_update([])
    # the critic's and the auxiliary optimizer each move an entry by at most ~lr
    assert 1.5 * LR < delta.abs().max() <= 2 * LR * 1.01
    assert (delta != 0).float().mean() > 0.5 and grad.norm() > 0


def test_flags_are_off_by_default_and_plain_path_is_deterministic():
    rc = typed(compose([]))
    assert rc.agent.compile is False and rc.agent.amp is False
    (m1, d1, g1), (m2, d2, g2) = run_update([]), run_update([])
    assert m1 == m2 and torch.equal(d1, d2) and torch.equal(g1, g2)


def test_amp_matches_plain_path_approximately():
    plain, d_plain, g_plain = run_update([])
    amp, d_amp, g_amp = run_update(["agent.amp=true"])
    for key in ("critic_loss", "taco_loss", "curl_loss", "actor_loss", "aux_loss"):
        assert amp[key] == pytest.approx(plain[key], rel=0.05, abs=0.02), key
    # bfloat16 forward passes: gradients within ~10%; a few small-gradient entries flip their Adam step.
    # Dropping the critic's gradient into the encoder gives cosine ~0.65; halving a loss, gradient error ~0.5.
    assert torch.nn.functional.cosine_similarity(d_amp, d_plain, dim=0) > 0.9
    assert relative_error(d_amp, d_plain) < 0.5
    assert relative_error(g_amp, g_plain) < 0.25


@pytest.mark.slow
def test_compile_matches_plain_path():
    plain, d_plain, g_plain = run_update([])
    comp, d_comp, g_comp = run_update(["agent.compile=true"])
    for key in plain:
        assert comp[key] == pytest.approx(plain[key], rel=1e-4, abs=1e-5), key
    # the same float32 math in another kernel order: the Adam steps agree except for a few near-zero-gradient
    # entries whose rounding flips their sign; that moves the auxiliary step's gradient a little. Measured over
    # three runs (they vary with inductor's kernel choice): gradient error 3e-6..0.009, flipped entries
    # 3e-5..0.0016. bfloat16 (amp) gives 0.09 and 0.3; a path that drops or halves a loss, 0.2..0.8.
    assert relative_error(g_comp, g_plain) < 0.03
    assert ((d_comp - d_plain).abs() > 1e-6).float().mean() < 0.01
    assert relative_error(d_comp, d_plain) < 0.2
