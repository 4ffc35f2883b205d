"""Time one update of the online agent (``repro bench`` without --offline; the roofline builds its agents here
too): built from its agent file, seeded 0, fed one synthetic batch again and again."""

from __future__ import annotations

import statistics
from typing import TYPE_CHECKING, Any

from repro.bench import SPEEDUP_FLAGS
from repro.bench.clock import timed

if TYPE_CHECKING:
    import torch


def synthetic_batch(B: int, K: int, A: int, device: str) -> dict[str, torch.Tensor]:
    """A batch of ``B`` random frame stacks, actions (``A`` dims, ``K`` steps) and rewards on ``device``, seeded 0."""
    import torch

    g = torch.Generator().manual_seed(0)
    u8 = lambda: torch.randint(0, 256, (B, 9, 84, 84), dtype=torch.uint8, generator=g).to(device)  # noqa: E731
    return {"obs": u8(), "next_obs": u8(), "future_obs": u8(),
            "action": (torch.rand(B, A, generator=g) * 2 - 1).to(device),
            "action_seq": (torch.rand(B, K, A, generator=g) * 2 - 1).to(device),
            "reward": torch.rand(B, 1, generator=g).to(device), "discount": torch.full((B, 1), 0.97, device=device),
            "reward_ksum": torch.rand(B, 1, generator=g).to(device)}


def build_agent(algo: str, batch_size: int, task: str, device: str, flags: list[str]) -> tuple[Any, Any]:
    """The online agent of agent file ``algo`` at ``batch_size`` for ``task`` with the overrides ``flags``, seeded
    0, and its typed run config."""
    import torch

    from repro.agent.agent import Agent
    from repro.config.compose import compose, typed
    from repro.envs import get_task

    rc = typed(compose([f"agent={algo}", f"task={task}", f"agent.batch_size={batch_size}", *flags]))
    torch.manual_seed(0)
    return Agent(rc.agent, (9, 84, 84), get_task(task).action_dim, device=device), rc


def time_update(algo: str, batch_size: int, task: str = "cheetah_run", repeats: int = 2,
                device: str = "cpu", speedup: str = "plain", warmup: int = 1) -> dict:
    """Median wall-clock seconds of one full agent update, over ``repeats`` timed updates after ``warmup``
    untimed ones (same batch every time)."""

    agent, rc = build_agent(algo, batch_size, task, device, SPEEDUP_FLAGS[speedup])
    batch = synthetic_batch(batch_size, rc.agent.K, agent.action_dim, device)
    for _ in range(warmup):
        agent.update(batch, step=10**6)
    times = [timed(lambda: agent.update(batch, step=10**6), device)[1] for _ in range(repeats)]
    seconds = statistics.median(times)
    # one update every 2 agent steps at action repeat 2 = 4 frames per update (update-bound estimate)
    fps = rc.train.update_every_steps * rc.env.action_repeat / seconds
    return {"algo": algo, "batch_size": batch_size, "speedup": speedup, "update_seconds": round(seconds, 4),
            "fps_estimate": round(fps, 3), "repeats": repeats, "warmup": warmup}


