"""The pieces every update benchmark shares (``repro bench``, ``--roofline``, repro/bench/agreement.py): a synthetic
batch, an agent built from its agent file, and timed updates of several paths alternated."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import torch


def _batch(B: int, K: int, A: int, device: str, seed: int = 0, image: int = 84) -> dict[str, torch.Tensor]:
    import torch

    g = torch.Generator().manual_seed(seed)
    u8 = lambda: torch.randint(0, 256, (B, 9, image, image), dtype=torch.uint8, generator=g).to(device)  # noqa: E731
    return {"obs": u8(), "next_obs": u8(), "future_obs": u8(),
            "action": (torch.rand(B, A, generator=g) * 2 - 1).to(device),
            "action_seq": (torch.rand(B, K, A, generator=g) * 2 - 1).to(device),
            "reward": torch.rand(B, 1, generator=g).to(device), "discount": torch.full((B, 1), 0.97, device=device),
            "reward_ksum": torch.rand(B, 1, generator=g).to(device)}


def build_agent(algo: str, batch_size: int, task: str, device: str, flags: list[str], image: int = 84
                ) -> tuple[Any, Any]:
    """The online agent of agent file ``algo`` at ``batch_size`` for ``task`` with the overrides ``flags``, seeded
    0, for stacks of 3 RGB frames of ``image`` pixels square, and its typed run config."""
    import torch

    from repro.agent.agent import Agent
    from repro.config.compose import compose, typed
    from repro.envs import get_task

    rc = typed(compose([f"agent={algo}", f"task={task}", f"agent.batch_size={batch_size}", *flags]))
    torch.manual_seed(0)
    return Agent(rc.agent, (9, image, image), get_task(task).action_dim, device=device), rc


def alternated_times(agents: dict[str, Any], batch: dict[str, torch.Tensor], warmup: int, repeats: int,
                     device: str) -> dict[str, list[float]]:
    """Seconds of each timed update per path (``agents`` by path, all on ``batch``): ``warmup`` untimed updates
    of each, then ``repeats`` rounds of one timed update of each path in turn (on CUDA synchronized before each
    clock reading)."""
    import torch

    def sync() -> None:
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    for agent in agents.values():
        for _ in range(warmup):
            agent.update(batch, step=10**6)
    times: dict[str, list[float]] = {path: [] for path in agents}
    for _ in range(repeats):
        for path, agent in agents.items():
            sync()
            t0 = time.perf_counter()
            agent.update(batch, step=10**6)
            sync()
            times[path].append(time.perf_counter() - t0)
    return times
