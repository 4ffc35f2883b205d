"""Opt-in speedups (agent.compile, agent.amp) against the plain path on the same weights and batch."""

import pytest
import torch

from repro.agent.agent import Agent
from repro.config import compose, typed
from test_losses import OBS, make_batch


def run_update(flags: list[str]) -> tuple[dict, dict]:
    rc = typed(compose(["agent.hidden_dim=64"] + flags))
    torch.manual_seed(0)
    agent = Agent(rc.agent, OBS, 4)
    torch.manual_seed(1)
    metrics = agent.update(make_batch(B=8), step=100)
    return metrics, {k: v.detach().clone() for k, v in agent.encoder.state_dict().items()}


def test_flags_are_off_by_default_and_plain_path_is_deterministic():
    rc = typed(compose([]))
    assert rc.agent.compile is False and rc.agent.amp is False
    assert run_update([])[0] == run_update([])[0]


def test_amp_matches_plain_path_approximately():
    plain, w_plain = run_update([])
    amp, w_amp = run_update(["agent.amp=true"])
    for key in ("critic_loss", "taco_loss", "curl_loss", "actor_loss"):
        assert amp[key] == pytest.approx(plain[key], rel=0.05, abs=0.02), key
    for k in w_plain:
        assert torch.allclose(w_plain[k], w_amp[k], atol=1e-3), k


@pytest.mark.slow
def test_compile_matches_plain_path():
    plain, w_plain = run_update([])
    comp, w_comp = run_update(["agent.compile=true"])
    for key in plain:
        assert comp[key] == pytest.approx(plain[key], rel=1e-4, abs=1e-5), key
    for k in w_plain:
        diff = (w_plain[k] - w_comp[k]).abs()
        # Adam normalises each gradient entry: rounding-level gradient differences can move a few
        # near-zero-gradient entries by up to one step (lr 1e-4 per optimizer); everything else agrees.
        assert diff.max() <= 2.5e-4, k
        assert (diff > 1e-6).float().mean() < 1e-3, k
