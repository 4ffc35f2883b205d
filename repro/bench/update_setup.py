"""What the update benchmarks time: one online agent built from its agent file, and a fixed synthetic batch
(used by `repro bench`'s update timing in ``cli.py`` and by ``roofline.py``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import torch


def synthetic_batch(B: int, K: int, A: int, device: str) -> dict[str, torch.Tensor]:
    """A fixed (seed 0) batch of B uint8 84x84 frame stacks and uniform actions, rewards and action sequences, as
    the replay returns it, on ``device``."""
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
