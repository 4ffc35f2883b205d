"""A fixed-seed record of a few online agent updates (losses, actions, every parameter and optimizer state).

Shared by tests/make_seam_fixture.py (which wrote tests/data/online_updates.json from the code before the
learner seam existed) and tests/test_seam.py (which recomputes it with today's code and compares bit for bit).
No environment is needed: the replay is filled with random frames.
"""

from __future__ import annotations

import hashlib

import numpy as np
import torch

from repro import api
from repro.config import compose, typed
from repro.replay import ReplayBuffer

AGENTS = ("taco", "drqv2")
UPDATES = 3
EPISODES, EPISODE_STEPS = 3, 12


def _digest(t: torch.Tensor) -> str:
    return hashlib.sha256(t.detach().cpu().contiguous().numpy().tobytes()).hexdigest()[:32]


def _flat(prefix: str, obj, out: dict[str, str]) -> None:
    """sha256 of every tensor in a nested state dict, keyed by its dotted path."""
    if isinstance(obj, torch.Tensor):
        out[prefix] = _digest(obj)
    elif isinstance(obj, dict):
        for k in sorted(obj, key=str):
            _flat(f"{prefix}.{k}" if prefix else str(k), obj[k], out)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _flat(f"{prefix}.{i}", v, out)
    else:
        out[prefix] = repr(obj)


def record(agent_name: str) -> dict:
    """Build the agent from its config (profile=tiny), fill a replay with random frames, run a few updates."""
    torch.set_num_threads(1)
    cfg = compose([f"agent={agent_name}", "profile=tiny", "task=cheetah_run", "seed=5"])
    rc = typed(cfg)
    obs_shape = (3 * rc.env.frame_stack, rc.env.image_size, rc.env.image_size)
    action_dim = 6
    agent = api.build_agent(rc, obs_shape, action_dim, "cpu")
    buffer = ReplayBuffer(rc.replay.capacity, (3, *obs_shape[1:]), action_dim, rc.env.frame_stack,
                          rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=rc.seed)
    rng = np.random.default_rng(123)
    for _ in range(EPISODES):
        buffer.start_episode(rng.integers(0, 256, (3, *obs_shape[1:]), dtype=np.uint8))
        for _ in range(EPISODE_STEPS):
            buffer.add(rng.uniform(-1, 1, action_dim).astype(np.float32), float(rng.normal()), 1.0,
                       rng.integers(0, 256, (3, *obs_shape[1:]), dtype=np.uint8))
        buffer.end_episode()
    obs = rng.integers(0, 256, obs_shape, dtype=np.uint8)
    out: dict = {"torch": torch.__version__, "metrics": [], "actions": [],
                 "parameter_counts": [list(r) for r in agent.parameter_counts()],
                 "metric_names": list(agent.metric_names())}
    step = 2000
    for i in range(UPDATES):
        batch = buffer.sample(rc.agent.batch_size, **agent.sample_options)
        out["metrics"].append(agent.update(batch, step + i))
        out["actions"].append([agent.act(obs, step + i, eval_mode=False).tolist(),
                               agent.act(obs, step + i, eval_mode=True).tolist()])
    state: dict[str, str] = {}
    _flat("", agent.state_dict(), state)
    out["state"] = state
    return out


def record_all() -> dict:
    return {name: record(name) for name in AGENTS}
